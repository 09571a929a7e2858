// Minimal leveled logging to stderr: "2026-11-21T10:00:00.123Z I coordinator: message".
// Thread-safe; the level is process-wide (MOTIONPIPE_LOG=debug|info|warn|error).
#pragma once

#include <sstream>
#include <string>

namespace motionpipe {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
// Parses "debug", "info", "warn", "error"; returns false on anything else.
bool ParseLogLevel(const std::string& text, LogLevel* level);
void LogLine(LogLevel level, const std::string& component, const std::string& message);

namespace internal {
// Swallows the stream expression so that MP_LOG is a single expression (safe inside if/else).
struct LogVoidify {
  void operator&(std::ostream&) {}
};
class LogMessage {
 public:
  LogMessage(LogLevel level, const char* component) : level_(level), component_(component) {}
  ~LogMessage() { LogLine(level_, component_, stream_.str()); }
  std::ostringstream& stream() { return stream_; }

 private:
  LogLevel level_;
  const char* component_;
  std::ostringstream stream_;
};
}  // namespace internal

}  // namespace motionpipe

#define MP_LOG(level, component)                                  \
  !(::motionpipe::LogLevel::level >= ::motionpipe::GetLogLevel()) \
      ? (void)0                                                   \
      : ::motionpipe::internal::LogVoidify() &                    \
            ::motionpipe::internal::LogMessage(::motionpipe::LogLevel::level, component).stream()
