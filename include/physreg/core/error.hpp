// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Errors: bad input throws physreg::Error naming the item, the value and the reason.
#include <filesystem>
#include <fmt/format.h>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace physreg {

class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// An input file or directory that is not there (Python sees FileNotFoundError).
class MissingFileError : public Error {
public:
    using Error::Error;
};

// Throws Error with a fmt-formatted message.
template <typename... Args>
[[noreturn]] void fail(fmt::format_string<Args...> format, Args&&... args)
{
    throw Error(fmt::format(format, std::forward<Args>(args)...));
}

/// Throws MissingFileError with a fmt-formatted message.
template <typename... Args>
[[noreturn]] void fail_missing_file(fmt::format_string<Args...> format, Args&&... args)
{
    throw MissingFileError(fmt::format(format, std::forward<Args>(args)...));
}

/// `value` (read from a file as a number) as an integer of type T. Throws Error "<what>: <item>
/// must be a whole number in [min, max] (got v)" for fractions, NaN/Inf or values out of T's range,
/// which a plain cast would truncate or turn into undefined behaviour.
template <typename T>
T to_integer(double value, const std::string& what, const char* item)
{
    constexpr double lowest = static_cast<double>(std::numeric_limits<T>::lowest());
    constexpr double highest = static_cast<double>(std::numeric_limits<T>::max());
    // `highest` may round up to 2^63 / 2^64 for 64-bit T, hence < rather than <=.
    if (!(value >= lowest && value < highest) || value != std::floor(value))
        fail("{}: {} must be a whole number in [{}, {}] (got {})", what, item, std::numeric_limits<T>::lowest(), std::numeric_limits<T>::max(), value);
    return static_cast<T>(value);
}

/// The whole of `text` as a number, as std::stod reads it (NaN and Inf included: callers decide), or
/// nothing when it is not a number or has anything after the number.
std::optional<double> parse_number(const std::string& text);
/// "1,2.5,4" → numbers; Error naming `name` for an item that is not a number or an empty list.
std::vector<double> parse_number_list(const std::string& text, const std::string& name);

/// Throws MissingFileError "<what>: file does not exist" unless `path` exists.
void require_existing_file(const std::filesystem::path& path, const std::string& what);

} // namespace physreg

// Always-on check for cheap invariants and input validation.
#define PHYSREG_VERIFY(condition, ...)                                                             \
    do {                                                                                           \
        if (!(condition)) ::physreg::fail(__VA_ARGS__);                                            \
    } while (false)
