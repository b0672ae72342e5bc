// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/log.hpp"

#include <mutex>
#include <spdlog/sinks/stdout_color_sinks.h>

namespace physreg {
namespace {
std::mutex g_mutex;
std::shared_ptr<spdlog::logger> g_logger;
} // namespace

std::shared_ptr<spdlog::logger> logger()
{
    std::lock_guard lock(g_mutex);
    if (!g_logger) {
        g_logger = spdlog::stderr_color_mt("physreg");
        g_logger->set_pattern("[%^%l%$] %v");
        g_logger->set_level(spdlog::level::info);
    }
    return g_logger;
}

void set_logger(std::shared_ptr<spdlog::logger> replacement)
{
    std::lock_guard lock(g_mutex);
    g_logger = std::move(replacement);
}

} // namespace physreg
