// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Where an explicit-dynamics run executes (`physreg simulate --device`, case key solver.device).
// Kept apart from the GPU solver so that readers of cases need none of it.
#include <string>

namespace physreg {

enum class Device { cpu, gpu, gpu_emulation };
Device parse_device(const std::string& text); ///< cpu | gpu | gpu-emulation; throws Error otherwise
std::string to_string(Device device);

} // namespace physreg
