#include "polycube/io/text_reader.h"

#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "polycube/core/error.h"

namespace polycube::io {

std::string read_file(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(ErrorKind::Parse, path + ": no such file");
  if (fs::is_directory(path, ec)) throw Error(ErrorKind::Parse, path + ": is a directory, not a mesh file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorKind::Parse, path + ": cannot open for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  std::string s = ss.str();
  if (s.empty()) throw Error(ErrorKind::Parse, path + ": file is empty");
  return s;
}

static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

bool TextReader::next(std::string_view& tok) {
  for (;;) {
    while (pos_ < data_.size() && is_space(data_[pos_])) {
      if (data_[pos_] == '\n') ++cur_;
      ++pos_;
    }
    if (pos_ >= data_.size()) return false;
    if (comment_ && data_[pos_] == comment_) {
      while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_;
      continue;
    }
    break;
  }
  size_t b = pos_;
  while (pos_ < data_.size() && !is_space(data_[pos_])) ++pos_;
  tok = data_.substr(b, pos_ - b);
  line_ = cur_;
  return true;
}

std::string_view TextReader::expect(const char* what) {
  std::string_view t;
  if (!next(t)) {
    // Report the line of the last token read: where the data stops.
    fail(std::string("unexpected end of file while reading ") + what + " (file truncated?)");
  }
  return t;
}

double TextReader::read_double(const char* what) {
  std::string_view t = expect(what);
  double v;
  if (!parse_double(t, v)) fail(std::string("expected a number for ") + what + ", found '" + std::string(t) + "'");
  return v;
}

long long TextReader::read_int(const char* what) {
  std::string_view t = expect(what);
  long long v;
  if (!parse_int(t, v)) fail(std::string("expected an integer for ") + what + ", found '" + std::string(t) + "'");
  return v;
}

bool TextReader::next_line(std::string_view& line) {
  while (pos_ < data_.size()) {
    size_t e = data_.find('\n', pos_);
    if (e == std::string_view::npos) e = data_.size();
    std::string_view l = data_.substr(pos_, e - pos_);
    line_ = cur_;
    pos_ = e < data_.size() ? e + 1 : e;
    ++cur_;
    if (comment_) {
      size_t c = l.find(comment_);
      if (c != std::string_view::npos) l = l.substr(0, c);
    }
    size_t a = 0;
    while (a < l.size() && is_space(l[a])) ++a;
    size_t b = l.size();
    while (b > a && is_space(l[b - 1])) --b;
    if (b > a) {
      line = l.substr(a, b - a);
      return true;
    }
  }
  return false;
}

void TextReader::fail(const std::string& message) const {
  throw Error(ErrorKind::Parse, path_ + ":" + std::to_string(line_) + ": " + message);
}

void split(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    size_t b = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
}

bool parse_double(std::string_view tok, double& v) {
  if (tok.empty()) return false;
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (*b == '+') ++b;
  auto r = std::from_chars(b, e, v);
  if (r.ec == std::errc() && r.ptr == e) return true;
  // from_chars rejects forms like "1.#INF"; strtod handles "inf"/"nan" consistently with from_chars,
  // so fall back only to catch locale-independent oddities.
  std::string s(tok);
  char* end = nullptr;
  errno = 0;
  v = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && !s.empty();
}

bool parse_int(std::string_view tok, long long& v) {
  if (tok.empty()) return false;
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (*b == '+') ++b;
  auto r = std::from_chars(b, e, v);
  return r.ec == std::errc() && r.ptr == e;
}

}  // namespace polycube::io
