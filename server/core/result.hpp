// Expected failures as values. A broken contract is HS_CHECK (core/check.hpp), not an Error.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace hs {

enum class ErrorCode {
    kInvalidArgument,  // the caller's input is malformed or out of range
    kNotFound,         // a file or named item does not exist
    kParse,            // a file exists but its content is malformed
    kUnsupported,      // well-formed, but this build or device cannot do it
    kDevice,           // the GPU or driver failed (device lost, out of memory)
    kIo,               // reading or writing a file failed
};

const char* to_string(ErrorCode code);

struct Error {
    ErrorCode code;
    std::string message;  // a sentence a person can act on: what, where, what was expected
};

inline Error make_error(ErrorCode code, std::string message) {
    return Error{code, std::move(message)};
}

// Result<T>: either a T or an Error. Result<void> carries only success or an Error.
template <typename T>
class [[nodiscard]] Result {
public:
    Result(T value) : v_(std::move(value)) {}
    Result(Error error) : v_(std::move(error)) {}

    bool ok() const { return v_.index() == 0; }
    explicit operator bool() const { return ok(); }

    T& value() & { return std::get<0>(v_); }
    const T& value() const& { return std::get<0>(v_); }
    T&& value() && { return std::get<0>(std::move(v_)); }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }
    T& operator*() & { return value(); }

    const Error& error() const { return std::get<1>(v_); }

private:
    std::variant<T, Error> v_;
};

template <>
class [[nodiscard]] Result<void> {
public:
    Result() = default;
    Result(Error error) : e_(std::move(error)) {}
    bool ok() const { return !e_.has_value(); }
    explicit operator bool() const { return ok(); }
    const Error& error() const { return *e_; }

private:
    std::optional<Error> e_;
};

}  // namespace hs

// Propagates an Error from an expression yielding Result<...>.
#define HS_TRY(expr)                  \
    do {                              \
        auto hs_try_r_ = (expr);      \
        if (!hs_try_r_.ok()) {        \
            return hs_try_r_.error(); \
        }                             \
    } while (0)

#define HS_CONCAT_INNER_(a, b) a##b
#define HS_CONCAT_(a, b) HS_CONCAT_INNER_(a, b)
// HS_ASSIGN_OR_RETURN(auto x, make_x()); binds the value or returns the Error.
#define HS_ASSIGN_OR_RETURN(lhs, expr) \
    HS_ASSIGN_OR_RETURN_IMPL_(HS_CONCAT_(hs_r_, __LINE__), lhs, expr)
#define HS_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
    auto tmp = (expr);                            \
    if (!tmp.ok()) {                              \
        return tmp.error();                       \
    }                                             \
    lhs = std::move(tmp).value()
