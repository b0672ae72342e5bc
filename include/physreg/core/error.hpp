#pragma once
// Errors: bad input throws physreg::Error naming the item, the value and the reason.
#include <fmt/format.h>
#include <stdexcept>
#include <string>

namespace physreg {

class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// Throws Error with a fmt-formatted message.
template <typename... Args>
[[noreturn]] void fail(fmt::format_string<Args...> format, Args&&... args)
{
    throw Error(fmt::format(format, std::forward<Args>(args)...));
}

} // namespace physreg

// Always-on check for cheap invariants and input validation.
#define PHYSREG_VERIFY(condition, ...)                                                             \
    do {                                                                                           \
        if (!(condition)) ::physreg::fail(__VA_ARGS__);                                            \
    } while (false)
