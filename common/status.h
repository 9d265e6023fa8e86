// Status: a cheap error value with a code and a message that names the field and the problem
// (after LevelDB's Status). Core code returns Status; the server maps codes to gRPC status at the edge.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace vb {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,     // bad input: a spec, a file, an RPC field
  kNotFound,
  kAlreadyExists,
  kFailedPrecondition,  // the world is not in the state the call needs (e.g. bench cannot do it)
  kOutOfRange,
  kResourceExhausted,
  kUnavailable,         // a device or service is not there right now
  kDataLoss,            // stored or received data is corrupt
  kAborted,             // stopped on purpose: cancel, safety trip
  kInternal,            // a bug: an invariant did not hold
};

class [[nodiscard]] Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status InvalidArgument(std::string msg) { return {StatusCode::kInvalidArgument, std::move(msg)}; }
  static Status NotFound(std::string msg) { return {StatusCode::kNotFound, std::move(msg)}; }
  static Status AlreadyExists(std::string msg) { return {StatusCode::kAlreadyExists, std::move(msg)}; }
  static Status FailedPrecondition(std::string msg) { return {StatusCode::kFailedPrecondition, std::move(msg)}; }
  static Status OutOfRange(std::string msg) { return {StatusCode::kOutOfRange, std::move(msg)}; }
  static Status ResourceExhausted(std::string msg) { return {StatusCode::kResourceExhausted, std::move(msg)}; }
  static Status Unavailable(std::string msg) { return {StatusCode::kUnavailable, std::move(msg)}; }
  static Status DataLoss(std::string msg) { return {StatusCode::kDataLoss, std::move(msg)}; }
  static Status Aborted(std::string msg) { return {StatusCode::kAborted, std::move(msg)}; }
  static Status Internal(std::string msg) { return {StatusCode::kInternal, std::move(msg)}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  std::string ToString() const;

  // Prefixes the message with context, e.g. a field path or a file name: "spec.duration_s: must be > 0".
  Status WithContext(std::string_view context) const;
  // For messages that start with a field path: "duty: ..." in "segments[0]" becomes "segments[0].duty: ...".
  Status InField(std::string_view parent) const;

 private:
  Status(StatusCode code, std::string msg) : code_(code), message_(std::move(msg)) {}
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

std::string_view StatusCodeName(StatusCode code);

// A value or the Status that says why there is none.
template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}                        // NOLINT: implicit by design
  StatusOr(Status status) : status_(std::move(status)) {                // NOLINT: implicit by design
    if (status_.ok()) status_ = Status::Internal("StatusOr built from an OK status without a value");
  }
  bool ok() const { return status_.ok(); }
  const Status& status() const { return status_; }
  T& value() & { return *value_; }
  const T& value() const& { return *value_; }
  T&& value() && { return std::move(*value_); }
  T* operator->() { return &*value_; }
  const T* operator->() const { return &*value_; }
  T& operator*() & { return *value_; }
  const T& operator*() const& { return *value_; }

 private:
  Status status_;
  std::optional<T> value_;
};

}  // namespace vb

// Returns early from the enclosing function when `expr` is not ok.
#define VB_RETURN_IF_ERROR(expr)          \
  do {                                    \
    ::vb::Status vb_status_ = (expr);     \
    if (!vb_status_.ok()) return vb_status_; \
  } while (0)

// `lhs = value of expr` (a StatusOr), or return its status from the enclosing function. lhs may declare:
// VB_ASSIGN_OR_RETURN(auto rows, Query(...));
#define VB_STATUS_CONCAT_INNER_(a, b) a##b
#define VB_STATUS_CONCAT_(a, b) VB_STATUS_CONCAT_INNER_(a, b)
#define VB_ASSIGN_OR_RETURN(lhs, expr) VB_ASSIGN_OR_RETURN_IMPL_(VB_STATUS_CONCAT_(vb_status_or_, __LINE__), lhs, expr)
#define VB_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                              \
  if (!tmp.ok()) return tmp.status();             \
  lhs = std::move(tmp).value()
