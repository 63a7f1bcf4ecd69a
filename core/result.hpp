// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Value-or-error for everything that can fail on input or hardware. Exceptions are not used
// across hardware or file boundaries; asserts are for bugs only.

#include <cassert>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace imucal {

enum class Errc {
  kInvalidArgument,   // the caller passed something out of range or malformed
  kNotFound,          // a file, device, key or stream does not exist
  kAlreadyExists,     // an output that must not be replaced exists (the caller may allow it)
  kIo,                // a read or write failed at the OS level
  kCorrupt,           // data exists but is damaged or truncated
  kUnsupported,       // a valid request this build or device cannot serve
  kDevice,            // hardware misbehaved (wrong WHO_AM_I, bus error, ...)
  kTimeout,           // something did not happen in time
  kInsufficientData,  // the recording does not contain what the method needs
  kNewerVersion,      // data a newer imucal wrote: not damage; that imucal (or an update) reads it
  kSolverFailed,      // an estimator did not converge or is ill-conditioned
  kInternal,          // a bug
};

const char* errc_name(Errc code);

/// An option that would resolve an error, named as the library's option field ("rate_hz",
/// "units", "allow_damaged"), with the value to give it when one follows from the error ("raw").
/// Libraries describe the problem in their own words and attach remedies; each program shows
/// them in its own terms (the CLI as its flags, the service as its settings).
struct Remedy {
  std::string option;
  std::string value;
};

struct Error {
  Errc code = Errc::kInternal;
  std::string message;
  std::vector<Remedy> remedies;

  /// The message with a prefix, for adding context while an error travels up.
  Error context(const std::string& where) const { return {code, where + ": " + message, remedies}; }
  /// The same error with one more remedy.
  Error with_remedy(std::string option, std::string value = {}) const {
    Error e = *this;
    e.remedies.push_back({std::move(option), std::move(value)});
    return e;
  }
};

template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}      // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & {
    assert(ok());
    return std::get<0>(v_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<0>(v_);
  }
  T&& value() && {
    assert(ok());
    return std::get<0>(std::move(v_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const {
    assert(!ok());
    return std::get<1>(v_);
  }

 private:
  std::variant<T, Error> v_;
};

template <>
class [[nodiscard]] Result<void> {
 public:
  Result() = default;
  Result(Error error) : error_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return !error_.has_value(); }
  explicit operator bool() const { return ok(); }
  const Error& error() const {
    assert(!ok());
    return *error_;
  }

 private:
  std::optional<Error> error_;
};

using Status = Result<void>;

inline Error make_error(Errc code, std::string message) { return Error{code, std::move(message), {}}; }

}  // namespace imucal

/// Propagate an error from an expression returning Result/Status.
#define IMUCAL_TRY(expr)                 \
  do {                                   \
    auto imucal_try_result_ = (expr);    \
    if (!imucal_try_result_.ok()) {      \
      return imucal_try_result_.error(); \
    }                                    \
  } while (false)
