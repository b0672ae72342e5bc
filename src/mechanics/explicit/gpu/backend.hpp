// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The GPU path's two back ends behind one interface: CUDA (cuda_steps.cu, built when the CUDA
// toolkit is found) and the host emulation (in gpu_tled.cpp), which runs the same kernels
// (tled_step_kernels.hpp) on the CPU.
#include "physreg/mechanics/explicit/gpu_tled.hpp"
#include "host_model.hpp"

#include <memory>
#include <vector>


namespace physreg {

class GpuTledSolver::Backend {
public:
    virtual ~Backend() = default;
    /// Loads changed (constrained, prescribed, external of the host model).
    virtual void set_loads(const gpu::HostModel& model) = 0;
    virtual void upload_state(const std::vector<double>& u, const std::vector<double>& u_prev) = 0;
    virtual void download_state(std::vector<double>& u, std::vector<double>& u_prev) = 0;
    /// Runs one step per entry: load factors now (s) and at the next step (sn). Stops after the
    /// first step that inverts an element or leaves |u| ≤ limit_mm.
    virtual gpu::ChunkReport run(const std::vector<double>& s, const std::vector<double>& sn, double limit_mm) = 0;
};

namespace gpu {
std::unique_ptr<GpuTledSolver::Backend> make_host_backend(const HostModel& model);
/// Throws Error naming what is missing when this build has no CUDA or the machine no device.
std::unique_ptr<GpuTledSolver::Backend> make_cuda_backend(const HostModel& model);
} // namespace gpu

} // namespace physreg
