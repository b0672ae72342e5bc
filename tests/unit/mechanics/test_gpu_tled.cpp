// SPDX-License-Identifier: GPL-3.0-or-later
// The GPU path (issue 45): its algorithm (element-force storage, node gather) run on the host
// against the CPU path; on the device when this machine has one; clean refusals otherwise.
#include "physreg/mechanics/explicit/gpu_tled.hpp"
#include "physreg/core/error.hpp"
#include "mechanics_fixtures.hpp"

#include <gtest/gtest.h>

namespace physreg::test {
namespace {

struct Run {
    std::vector<double> u;
    double peak = 0.0;
};

/// A 6 × 5 × 12 block (2 mm) on a fixed base, its top pushed down 1.5 mm and pulled sideways by a
/// force, run for `duration_s` of explicit dynamics.
struct Case {
    VolumeMesh mesh = block_mesh(6, 5, 12, 2.0);
    TledModel model{mesh, one_tissue(3e3, 0.45), {}};
    Loads loads;
    Case()
    {
        loads.constraints.push_back({"base", nodes_at(mesh, 2, 0.0), {true, true, true}, Vec3::Zero()});
        loads.constraints.push_back({"top", nodes_at(mesh, 2, 24.0), {false, false, true}, Vec3(0, 0, -1.5)});
        loads.external_forces_n.assign(3 * mesh.node_count(), 0.0);
        for (auto n : nodes_at(mesh, 0, 12.0)) loads.external_forces_n[3 * n + 1] = 2e-4; // N, on the x = 12 mm face
        loads.ramp_time_s = 0.01;
    }
};

double largest_difference(const std::vector<double>& a, const std::vector<double>& b, double* peak)
{
    double worst = 0.0;
    *peak = 0.0;
    for (std::size_t k = 0; k < a.size(); ++k) {
        worst = std::max(worst, std::abs(a[k] - b[k]));
        *peak = std::max(*peak, std::abs(b[k]));
    }
    return worst;
}

std::vector<double> cpu_run(const Case& c, double duration_s)
{
    TledSolver<double> solver(c.model);
    solver.set_loads(c.loads);
    solver.advance(duration_s);
    return solver.displacement_mm();
}

TEST(GpuPath, TheEmulatedGpuStepEqualsTheCpuPath)
{
    const Case c;
    const double duration = 0.02; // several hundred steps, through the ramp and beyond
    const auto cpu = cpu_run(c, duration);
    GpuTledSolver gpu(c.model, Device::gpu_emulation);
    gpu.set_loads(c.loads);
    gpu.advance(duration);
    TledSolver<double> reference(c.model);
    reference.set_loads(c.loads);
    reference.advance(duration);
    EXPECT_EQ(gpu.steps(), reference.steps());
    double peak = 0.0;
    const double worst = largest_difference(gpu.displacement_mm(), cpu, &peak);
    EXPECT_GT(peak, 0.5); // the top moved (mm)
    EXPECT_LT(worst, 1e-10 * peak) << "steps " << gpu.steps() << ", peak " << peak << " mm";
}

TEST(GpuPath, TheDeviceEqualsTheCpuPathOrRefusesNamingWhy)
{
    const Case c;
    const GpuStatus status = gpu_status();
    if (!status.usable()) {
        EXPECT_FALSE(status.reason.empty());
        try {
            GpuTledSolver gpu(c.model, Device::gpu);
            FAIL() << "a GPU solver was made without a usable device";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(status.reason), std::string::npos) << e.what();
        }
        GTEST_SKIP() << "no GPU here: " << status.reason;
    }
    const double duration = 0.02;
    const auto cpu = cpu_run(c, duration);
    GpuTledSolver gpu(c.model, Device::gpu);
    gpu.set_loads(c.loads);
    gpu.advance(duration);
    double peak = 0.0;
    const double worst = largest_difference(gpu.displacement_mm(), cpu, &peak);
    EXPECT_LT(worst, 1e-10 * peak) << status.device_name;
}

TEST(GpuPath, InversionIsReportedNotContinued)
{
    const Case c;
    Loads crush = c.loads;
    crush.constraints[1].displacement_mm = Vec3(0, 0, -30.0); // more than the block's 24 mm height
    crush.ramp_time_s = 1e-3;
    GpuTledSolver gpu(c.model, Device::gpu_emulation);
    gpu.set_loads(crush);
    try {
        gpu.advance(0.01);
        FAIL() << "a crushed block ran on";
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_TRUE(what.find("inverted") != std::string::npos || what.find("diverged") != std::string::npos) << what;
    }
}

TEST(GpuPath, OutsideItsScopeItRefusesClearly)
{
    const Case c;
    Loads with_tool = c.loads;
    Indenter tool;
    tool.name = "sphere";
    tool.radius_mm = 3;
    tool.path = {Vec3(6, 5, 30), Vec3(6, 5, 23)};
    with_tool.indenters.push_back(tool);
    GpuTledSolver gpu(c.model, Device::gpu_emulation);
    EXPECT_THROW(gpu.set_loads(with_tool), Error);
    const VolumeMesh tets = split_hexahedra_into_tetrahedra(block_mesh(2, 2, 2, 2.0));
    const TledModel tet_model(tets, one_tissue(3e3, 0.45), {});
    EXPECT_THROW(GpuTledSolver(tet_model, Device::gpu_emulation), Error);
    EXPECT_THROW(parse_device("cuda"), Error);
    EXPECT_EQ(parse_device("gpu-emulation"), Device::gpu_emulation);
}

} // namespace
} // namespace physreg::test
