// Always-on contract checks: a failing HS_CHECK is a programmer's bug. It logs file, line and
// message and aborts. Never compiled out. Expected failures use Result<T> (core/result.hpp).
#pragma once

namespace hs::detail {
[[noreturn]] void check_failed(const char* file, int line, const char* expr, const char* msg);
}

#define HS_CHECK(cond, msg)                                             \
    do {                                                                \
        if (!(cond)) [[unlikely]] {                                     \
            ::hs::detail::check_failed(__FILE__, __LINE__, #cond, msg); \
        }                                                               \
    } while (0)
