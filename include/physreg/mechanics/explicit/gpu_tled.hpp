// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// TLED explicit dynamics on an NVIDIA GPU (CUDA), optional at build time: a build without the
// CUDA toolkit, or a machine without a device, refuses with an error naming what is missing — it
// never falls back to the CPU unless asked (Device::gpu_emulation runs the GPU algorithm on the
// host: the check that the GPU path computes what the CPU path computes, on machines without one).
//
// The GPU step stores each element's nodal forces and gathers them per node (no colouring, no
// atomics; src/mechanics/explicit/gpu/tled_step_kernels.hpp). Scope: hexahedral meshes,
// Neo-Hookean or St Venant–Kirchhoff, prescribed displacements and external forces, double
// precision; tools (indenters) and tissue coupling stay on the CPU path (TledSolver).
#include "physreg/mechanics/explicit/device.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include <memory>
#include <string>
#include <vector>

namespace physreg {

/// What the GPU path can do on this machine.
struct GpuStatus {
    bool built = false;        ///< this physreg was compiled with the CUDA toolkit
    int devices = 0;           ///< CUDA devices the runtime sees
    std::string device_name;   ///< the first device's name
    std::string reason;        ///< why the GPU path cannot run here (empty when it can)
    bool usable() const { return built && devices > 0; }
};
GpuStatus gpu_status();

class GpuTledSolver {
public:
    /// Throws Error when the device cannot run (the reason from gpu_status()), or the model is
    /// outside the GPU path's scope (tetrahedra, another material law).
    GpuTledSolver(const TledModel& model, Device device = Device::gpu);
    ~GpuTledSolver();
    GpuTledSolver(const GpuTledSolver&) = delete;
    GpuTledSolver& operator=(const GpuTledSolver&) = delete;

    /// Constraints and external forces; indenters are refused (CPU path only).
    void set_loads(Loads loads);
    /// Explicit dynamics from the current state for `duration_s` at the model's stable step, as
    /// TledSolver::advance. Inversion or divergence throws Error naming the step (checked every
    /// 64 steps on the device) and leaves the state at the last check.
    void advance(double duration_s, const ProgressCallback& progress = {});
    void set_displacement(const std::vector<double>& u_mm);
    std::vector<double> displacement_mm() const;
    double time_s() const { return m_time; }
    long steps() const { return m_steps; }
    double time_step_s() const { return m_time_step; }
    Device device() const { return m_device; }

    /// The step's memory traffic and arithmetic per element-step, for roofline estimates:
    /// bytes moved by the two kernels and floating-point operations of the element kernel.
    static double bytes_per_element_step();
    static double flops_per_element_step();

    class Backend; ///< device memory and kernels (CUDA) or their host emulation

private:
    const TledModel& m_model;
    Device m_device;
    Loads m_loads;
    double m_time_step = 0.0, m_time = 0.0;
    long m_steps = 0;
    std::unique_ptr<Backend> m_backend;
};

} // namespace physreg
