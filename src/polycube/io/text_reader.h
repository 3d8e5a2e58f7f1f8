// Tokenizer for the text mesh formats. Keeps the line number of every token so that parse
// errors can say "file:line: ...". Throws Error(Parse) with that prefix.
#pragma once
#include <string>
#include <string_view>
#include <vector>

namespace polycube::io {

/// Reads a whole file into memory. Throws Error(Parse) if it cannot be opened, is a directory or is empty.
std::string read_file(const std::string& path);

class TextReader {
 public:
  /// `comment` starts a comment running to the end of the line (0 = no comments).
  TextReader(std::string_view data, std::string path, char comment = '#')
      : data_(data), path_(std::move(path)), comment_(comment) {}

  /// Next whitespace-separated token, false at end of data.
  bool next(std::string_view& tok);
  /// Next token or a "truncated" error mentioning `what`.
  std::string_view expect(const char* what);
  double read_double(const char* what);
  long long read_int(const char* what);

  /// Next non-empty line (comments stripped), false at end. Sets line().
  bool next_line(std::string_view& line);

  /// Line of the last token or line returned (1-based).
  int line() const { return line_; }
  /// Byte offset just after the last token.
  size_t pos() const { return pos_; }
  const std::string& path() const { return path_; }

  [[noreturn]] void fail(const std::string& message) const;

 private:
  std::string_view data_;
  std::string path_;
  char comment_;
  size_t pos_ = 0;
  int line_ = 1;   // line of last token
  int cur_ = 1;    // line at pos_
};

/// Splits a line into whitespace-separated tokens.
void split(std::string_view line, std::vector<std::string_view>& out);
/// Parses a full token as a number; false if it is not one (or has trailing garbage).
bool parse_double(std::string_view tok, double& v);
bool parse_int(std::string_view tok, long long& v);

}  // namespace polycube::io
