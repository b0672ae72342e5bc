// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/explicit/device.hpp"

#include "physreg/core/error.hpp"

namespace physreg {

Device parse_device(const std::string& text)
{
    if (text == "cpu") return Device::cpu;
    if (text == "gpu") return Device::gpu;
    if (text == "gpu-emulation") return Device::gpu_emulation;
    fail("device '{}': expected cpu, gpu or gpu-emulation (the GPU algorithm run on the host, for checking)", text);
}

std::string to_string(Device device)
{
    switch (device) {
    case Device::cpu: return "cpu";
    case Device::gpu: return "gpu";
    case Device::gpu_emulation: return "gpu-emulation";
    }
    return "?";
}

} // namespace physreg
