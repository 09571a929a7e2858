// Errors as values (LevelDB's Status): every fallible operation on a user path returns a Status or
// a Result<T>; exceptions are reserved for programmer errors and for LibTorch at the plugin
// boundary.
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace motionpipe {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,  // the caller passed something unusable (bad flag, bad config value)
  kNotFound,         // a file, key or name does not exist
  kDataLoss,         // a file exists but is truncated, corrupt or malformed
  kFailedPrecondition,
  kUnimplemented,
  kIoError,  // the operating system refused (permissions, disk full)
  kInternal,
};

// An error code plus a message that names the file and the problem. Cheap to copy when ok.
class Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return {}; }
  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "DataLoss: clip.npz: member 'poses.npy' is truncated".
  std::string ToString() const;
  // Returns a copy whose message is prefixed with `context: `.
  Status WithContext(const std::string& context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

Status InvalidArgument(std::string message);
Status NotFound(std::string message);
Status DataLoss(std::string message);
Status FailedPrecondition(std::string message);
Status Unimplemented(std::string message);
Status IoError(std::string message);
Status Internal(std::string message);

// A value or the Status explaining why there is none.
template <typename T>
class Result {
 public:
  Result(T value) : value_(std::move(value)) {}         // NOLINT(google-explicit-constructor)
  Result(Status status) : status_(std::move(status)) {  // NOLINT(google-explicit-constructor)
    assert(!status_.ok() && "Result constructed from an ok Status");
  }

  bool ok() const { return value_.has_value(); }
  const Status& status() const { return status_; }
  T& value() & {
    assert(ok());
    return *value_;
  }
  const T& value() const& {
    assert(ok());
    return *value_;
  }
  T&& value() && {
    assert(ok());
    return std::move(*value_);
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

 private:
  std::optional<T> value_;
  Status status_;
};

}  // namespace motionpipe

#define MP_CONCAT_INNER(a, b) a##b
#define MP_CONCAT(a, b) MP_CONCAT_INNER(a, b)

// Returns the Status from the enclosing function when it is not ok.
#define MP_RETURN_IF_ERROR(expr)              \
  do {                                        \
    ::motionpipe::Status mp_status_ = (expr); \
    if (!mp_status_.ok()) return mp_status_;  \
  } while (0)

#define MP_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                             \
  if (!tmp.ok()) return tmp.status();            \
  lhs = std::move(tmp).value()

// `MP_ASSIGN_OR_RETURN(auto x, ReadThing(path));`
#define MP_ASSIGN_OR_RETURN(lhs, expr) \
  MP_ASSIGN_OR_RETURN_IMPL(MP_CONCAT(mp_result_, __LINE__), lhs, expr)
