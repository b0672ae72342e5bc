// SPDX-License-Identifier: GPL-3.0-or-later
// Meshing time and peak memory for a 512×512×300 label volume at full resolution (one hexahedron
// per voxel), the size of an abdominal CT. Two occupancies: a liver-sized organ (≈ 1.6 l, about
// 4 % of the voxels, as in the MSD masks) and a whole-abdomen label (≈ 30 % of the voxels).
// Run: build/bin/bench_meshing --benchmark_out=bench/results/bench_meshing.json --benchmark_out_format=json
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/label_grid.hpp"

#include <benchmark/benchmark.h>
#include <sys/resource.h>

namespace {

using namespace physreg;

double peak_rss_mb()
{
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_maxrss / 1024.0; // Linux reports KiB
}

// Ellipsoids (semi-axes in mm) centred in a 512×512×300 volume of 0.75×0.75×1.0 mm voxels.
LabelVolume make_ct_sized_volume(double a, double b, double c)
{
    LabelVolume v;
    v.geometry.size = {512, 512, 300};
    v.geometry.spacing = Vec3(0.75, 0.75, 1.0);
    v.labels.assign(static_cast<std::size_t>(v.geometry.voxel_count()), 0);
#pragma omp parallel for schedule(static)
    for (int k = 0; k < 300; ++k)
        for (int j = 0; j < 512; ++j)
            for (int i = 0; i < 512; ++i) {
                const double x = (i - 255.5) * 0.75, y = (j - 255.5) * 0.75, z = (k - 149.5) * 1.0;
                const double r = x * x / (a * a) + y * y / (b * b) + z * z / (c * c);
                // a tumour-like inclusion so that two tissues meet
                const double t = ((x - 0.3 * a) * (x - 0.3 * a) + y * y + z * z) / 400.0;
                v.labels[static_cast<std::size_t>(i + 512 * (j + 512 * k))] = r <= 1.0 ? (t <= 1.0 ? 3 : 1) : 0;
            }
    return v;
}

void run(benchmark::State& state, const LabelVolume& volume)
{
    const TissueTable tissues = default_tissue_table();
    std::size_t cells = 0, nodes = 0;
    for (auto _ : state) {
        auto result = mesh_label_volume(volume, tissues, {}, "bench");
        cells = result.mesh.cell_count();
        nodes = result.mesh.node_count();
        benchmark::DoNotOptimize(result.mesh.cells.data());
    }
    state.counters["voxels"] = static_cast<double>(volume.geometry.voxel_count());
    state.counters["hexahedra"] = static_cast<double>(cells);
    state.counters["nodes"] = static_cast<double>(nodes);
    state.counters["peak_rss_mb"] = peak_rss_mb();
    state.counters["hexahedra_per_s"] = benchmark::Counter(static_cast<double>(cells), benchmark::Counter::kIsIterationInvariantRate);
}

void BM_MeshVoxels_512x512x300_Liver(benchmark::State& state)
{
    static const LabelVolume volume = make_ct_sized_volume(92, 71, 45); // 184 × 142 × 90 mm, ≈ 1.23 l
    run(state, volume);
}

void BM_MeshVoxels_512x512x300_Abdomen(benchmark::State& state)
{
    static const LabelVolume volume = make_ct_sized_volume(165, 125, 140); // ≈ 30 % of the voxels
    run(state, volume);
}

} // namespace

BENCHMARK(BM_MeshVoxels_512x512x300_Liver)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_MeshVoxels_512x512x300_Abdomen)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK_MAIN();
