// SPDX-License-Identifier: GPL-3.0-or-later
// TLED throughput: hexahedral element-steps per second of explicit dynamics (Neo-Hookean,
// ν = 0.49, hourglass control on) for 24×18×18 and 74×18×54 blocks, 1 and 2 threads, single and
// double precision; and the time and iterations to reach equilibrium for a 10 mm indentation of
// the 74×18×54 block by dynamic relaxation.
// Run: build/bin/bench_tled --benchmark_out=bench/results/bench_tled.json --benchmark_out_format=json
#include "physreg/mechanics/implicit/stiffness_assembly.hpp"
#include "physreg/mechanics/explicit/gpu_tled.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/core/openmp_wait.hpp"

#include <benchmark/benchmark.h>
#include <omp.h>

namespace {

using namespace physreg;

TissueTable tissues();

VolumeMesh block(int nx, int ny, int nz, double h)
{
    LabelVolume v;
    v.geometry.size = {nx, ny, nz};
    v.geometry.spacing = Vec3::Constant(h);
    v.geometry.origin = Vec3::Constant(h / 2);
    v.labels.assign(static_cast<std::size_t>(nx) * ny * nz, 1);
    return mesh_label_volume(v, tissues(), {}, "block").mesh;
}

TissueTable tissues()
{
    TissueTable t;
    t.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}};
    return t;
}

const VolumeMesh& mesh_of(int which)
{
    static const VolumeMesh small = block(24, 18, 18, 2.5);
    static const VolumeMesh large = block(74, 18, 54, 2.5);
    return which == 0 ? small : large;
}

/// The explicit benchmarks' loads: base fixed, top pushed 5 mm down over a 0.1 s ramp.
Loads base_fixed_top_pushed(const VolumeMesh& mesh)
{
    Loads loads;
    std::vector<std::int32_t> base, top;
    double z_max = 0;
    for (const auto& p : mesh.nodes) z_max = std::max(z_max, p[2]);
    for (std::size_t n = 0; n < mesh.node_count(); ++n) {
        if (mesh.nodes[n][2] < 1e-9) base.push_back(static_cast<std::int32_t>(n));
        if (mesh.nodes[n][2] > z_max - 1e-9) top.push_back(static_cast<std::int32_t>(n));
    }
    loads.constraints.push_back({"base", base, {true, true, true}, Vec3::Zero()});
    loads.constraints.push_back({"top", top, {false, false, true}, Vec3(0, 0, -5.0)});
    loads.ramp_time_s = 0.1;
    return loads;
}

// range(2), the force loop (issue 45 compares them in one run): 0 the default (bands of node
// numbers, contiguous runs, the box corner transform), 1 the colouring and general kernel used
// before, 2 bands and runs with the general kernel.
template <typename Real>
void BM_TledSteps(benchmark::State& state)
{
    const VolumeMesh& mesh = mesh_of(static_cast<int>(state.range(0)));
    const int threads = static_cast<int>(state.range(1));
    omp_set_num_threads(threads);
    TledOptions options;
    options.work_partition = state.range(2) == 1 ? TledOptions::WorkPartition::colouring : TledOptions::WorkPartition::automatic;
    options.box_elements = state.range(2) == 0;
    const TledModel model(mesh, tissues(), options);
    TledSolver<Real> solver(model);
    const Loads loads = base_fixed_top_pushed(mesh);
    solver.set_loads(loads);
    const double dt = model.time_step_s();
    const long steps_per_iteration = 200;
    for (auto _ : state) solver.advance(steps_per_iteration * dt * (1 - 1e-6));
    const double element_steps = double(model.element_count()) * steps_per_iteration;
    state.counters["elements"] = double(model.element_count());
    state.counters["threads"] = threads;
    state.counters["band_partition"] = model.band_partition() ? 1 : 0;
    state.counters["box_elements"] = solver.box_elements() ? 1 : 0;
    state.counters["element_steps_per_s"] = benchmark::Counter(element_steps, benchmark::Counter::kIsIterationInvariantRate);
}

// The GPU path on the same blocks and loads (double precision): skipped with the reason where this
// build or machine has no CUDA device. Run in the same invocation as BM_TledSteps<double> for the
// ratio (issue 45's target: ≥ 20× the 2-thread CPU path).
void BM_TledStepsGpu(benchmark::State& state)
{
    const GpuStatus status = gpu_status();
    if (!status.usable()) {
        state.SkipWithError(("no GPU: " + status.reason).c_str());
        return;
    }
    const VolumeMesh& mesh = mesh_of(static_cast<int>(state.range(0)));
    const TledModel model(mesh, tissues(), {});
    GpuTledSolver solver(model, Device::gpu);
    const Loads loads = base_fixed_top_pushed(mesh);
    solver.set_loads(loads);
    const double dt = model.time_step_s();
    const long steps_per_iteration = 2000;
    for (auto _ : state) solver.advance(steps_per_iteration * dt * (1 - 1e-6));
    state.counters["elements"] = double(model.element_count());
    state.SetLabel(status.device_name);
    state.counters["element_steps_per_s"] =
        benchmark::Counter(double(model.element_count()) * steps_per_iteration, benchmark::Counter::kIsIterationInvariantRate);
}

void BM_IndentationEquilibrium(benchmark::State& state)
{
    omp_set_num_threads(static_cast<int>(state.range(0)));
    const VolumeMesh& mesh = mesh_of(1);
    const TledModel model(mesh, tissues(), {});
    Loads loads;
    std::vector<std::int32_t> base;
    for (std::size_t n = 0; n < mesh.node_count(); ++n)
        if (mesh.nodes[n][2] < 1e-9) base.push_back(static_cast<std::int32_t>(n));
    loads.constraints.push_back({"base", base, {true, true, true}, Vec3::Zero()});
    Indenter tool;
    tool.name = "sphere";
    tool.radius_mm = 20;
    const double top = 54 * 2.5;
    tool.path = {Vec3(92.5, 22.5, top + 20), Vec3(92.5, 22.5, top + 10)}; // 10 mm deep at the top centre
    loads.indenters.push_back(tool);
    EquilibriumOptions options; // defaults: 1e-5 mm, residual 1e-4 of the largest nodal force
    long iterations = 0;
    bool converged = true;
    for (auto _ : state) {
        TledSolver<double> solver(model);
        solver.set_loads(loads);
        iterations = 0;
        for (int step = 1; step <= 4; ++step) { // four tool positions, warm-started
            const auto summary = solver.solve_equilibrium(options, step / 4.0);
            iterations += summary.iterations;
            converged = converged && summary.converged();
        }
    }
    state.counters["iterations"] = double(iterations);
    state.counters["converged"] = converged ? 1 : 0;
    state.counters["elements"] = double(model.element_count());
}

} // namespace

// Assembly of the tangent stiffness (implicit solvers) of the 24×18×18 block, Neo-Hookean, at a
// small deformation.
void BM_Assembly(benchmark::State& state)
{
    const VolumeMesh& mesh = mesh_of(0);
    const int threads = static_cast<int>(state.range(0));
    omp_set_num_threads(threads);
    const TledModel model(mesh, tissues(), {});
    const StiffnessAssembler assembler(model);
    SparseMatrix k = assembler.make_matrix();
    std::vector<double> u(3 * model.node_count()), f(u.size());
    for (std::size_t i = 0; i < u.size(); ++i) u[i] = 1e-3 * static_cast<double>(i % 7);
    for (auto _ : state) assembler.assemble(u.data(), f.data(), &k);
    state.counters["threads"] = threads;
    state.counters["elements_per_s"] =
        benchmark::Counter(double(model.element_count()), benchmark::Counter::kIsIterationInvariantRate);
}

BENCHMARK(BM_Assembly)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_TledSteps, double)->ArgsProduct({{0, 1}, {1, 2}, {0, 1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_TledSteps, float)->ArgsProduct({{0, 1}, {1, 2}, {0, 1, 2}})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_TledStepsGpu)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_IndentationEquilibrium)->Arg(2)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
// As the physreg program: idle OpenMP threads spin briefly (core/openmp_wait.hpp), unless
// GOMP_SPINCOUNT or OMP_WAIT_POLICY is set (bench/shared_load.sh compares the policies).
PHYSREG_OPENMP_SHORT_SPIN();

BENCHMARK_MAIN();
