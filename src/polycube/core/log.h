// Pluggable logging and progress. The library never prints: it calls these hooks, which the CLI
// (or any host application) connects to its own output. Default-constructed hooks do nothing.
#pragma once
#include <chrono>
#include <functional>
#include <string>

namespace polycube {

enum class LogLevel { Debug, Info, Warn };

struct Hooks {
  /// Receives every message of the library. Empty = discard.
  std::function<void(LogLevel, const std::string&)> log;
  /// Receives progress of long operations: stage name and fraction done in [0, 1]. Empty = discard.
  std::function<void(const std::string& stage, double fraction)> progress;

  void debug(const std::string& m) const { if (log) log(LogLevel::Debug, m); }
  void info(const std::string& m) const { if (log) log(LogLevel::Info, m); }
  void warn(const std::string& m) const { if (log) log(LogLevel::Warn, m); }
  void report(const std::string& stage, double f) const { if (progress) progress(stage, f); }
};

/// Wall-clock stopwatch.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace polycube
