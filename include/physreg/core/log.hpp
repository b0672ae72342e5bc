// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The library never prints: it logs through a replaceable spdlog logger (stderr by default).
#include <memory>
#include <spdlog/spdlog.h>

namespace physreg {

std::shared_ptr<spdlog::logger> logger();
void set_logger(std::shared_ptr<spdlog::logger> replacement);

} // namespace physreg
