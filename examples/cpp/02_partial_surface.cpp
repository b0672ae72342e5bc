// SPDX-License-Identifier: GPL-3.0-or-later
// Register an organ model to a partial intra-operative surface with the C++ library (paper 001's
// mode): the same pipeline as `physreg register-surface --labels L --cloud C` and Python's
// physreg.register_surface (examples/02_partial_surface.py makes the same organ and push).
//
//   example_02_partial_surface      an organ and a pushed cloud made here, checked (ctest runs this)
//
// Outside this build tree: find_package(physreg CONFIG REQUIRED) and link physreg::physreg.
#include "physreg/core/error.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"
#include "physreg/registration/surface/surface_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <set>

namespace {

using physreg::Vec3;

/// Two lobes (ellipsoids) on 2 mm voxels, centred near the origin (mm, LPS): a shape without
/// symmetries, as an organ is.
physreg::LabelVolume organ()
{
    physreg::LabelVolume v;
    v.geometry.size = {101, 71, 57};
    v.geometry.spacing = Vec3::Constant(2.0);
    v.geometry.origin = Vec3(-100, -70, -56);
    v.labels.resize(static_cast<std::size_t>(v.geometry.voxel_count()));
    for (int k = 0; k < 57; ++k)
        for (int j = 0; j < 71; ++j)
            for (int i = 0; i < 101; ++i) {
                const Vec3 x = v.geometry.index_to_physical(Vec3(i, j, k));
                const bool right = std::pow((x[0] + 15) / 70, 2) + std::pow(x[1] / 55, 2) + std::pow(x[2] / 42, 2) < 1;
                const bool left = std::pow((x[0] - 50) / 40, 2) + std::pow((x[1] + 10) / 35, 2) + std::pow((x[2] - 10) / 25, 2) < 1;
                v.labels[static_cast<std::size_t>(v.geometry.linear_index(i, j, k))] = right || left ? 1 : 0;
            }
    return v;
}

/// The tool's push (a made-up deformation, not physreg's model): a dent along -y centred at
/// (20, 55, 5), radius ~25 mm, 14 mm deep at the surface, halving every 28 mm of depth.
Vec3 pressed(const Vec3& p)
{
    const double dent = 14.0 * std::exp(-(std::pow(p[0] - 20, 2) + std::pow(p[2] - 5, 2)) / (2 * 25.0 * 25.0)) * std::pow(0.5, (55 - p[1]) / 28);
    return p - Vec3(0, dent, 0);
}

} // namespace

int main()
{
    try {
        const physreg::SurfaceModel model = physreg::surface_model_from_labels(organ(), {1}, 9.0, std::nullopt, 1, "the organ");
        physreg::PartialSurfaceCase c;
        c.mesh = model.mesh;
        c.surface = model.surface;
        c.quality = model.quality;
        // What the camera saw: 400 surface points of the upper half, pushed, with 0.3 mm noise.
        std::set<std::int32_t> upper;
        for (const auto& t : model.surface.triangles)
            for (const auto n : t)
                if (model.mesh.nodes[static_cast<std::size_t>(n)][1] > 10.0) upper.insert(n);
        std::vector<std::int32_t> seen(upper.begin(), upper.end());
        std::mt19937 rng(7);
        std::shuffle(seen.begin(), seen.end(), rng);
        seen.resize(std::min<std::size_t>(400, seen.size()));
        std::normal_distribution<double> noise(0.0, 0.3);
        for (const auto n : seen) c.cloud.points.push_back(pressed(model.mesh.nodes[static_cast<std::size_t>(n)]) + Vec3(noise(rng), noise(rng), noise(rng)));
        c.cloud.labels.assign(c.cloud.points.size(), 0); // 0: plain surface (no anatomical region)
        // A lesion 17 mm under the pressed spot, and where the push truly took it.
        const Vec3 lesion(18, 38, 4);
        c.landmarks = physreg::LandmarkSet{{"lesion", lesion, physreg::LandmarkType::tumour}};
        c.truth = physreg::LandmarkSet{{"lesion", pressed(lesion), physreg::LandmarkType::tumour}};

        physreg::PartialSurfaceSettings settings; // the command's defaults
        settings.noise = 0.3;                     // mm: the cloud's noise
        const physreg::PartialSurfaceResult r = physreg::register_surface(c, settings);

        const auto& s = r.summary;
        std::printf("answer written: %s\n", r.safeguard.answer.c_str());
        for (const char* name : {"at_rest", "rigid", "adjoint"})
            std::printf("%-8s lesion error %5.2f mm\n", name, s["methods"][name]["tre"]["all"]["mean_mm"].get<double>());
        std::printf("%s\n", s["predicted_error"]["statement"].get<std::string>().c_str());
        std::printf("lesion moved to (%.1f, %.1f, %.1f) mm\n", (*r.landmarks)[0].position[0], (*r.landmarks)[0].position[1], (*r.landmarks)[0].position[2]);

        // What the example promises: the lesion follows the push, closer than leaving the organ at rest.
        const double answer = s["methods"][r.safeguard.answer]["tre"]["all"]["mean_mm"].get<double>();
        const double at_rest = s["methods"]["at_rest"]["tre"]["all"]["mean_mm"].get<double>();
        if (!(answer < 0.5 * at_rest)) {
            std::fprintf(stderr, "example: the lesion error %.2f mm is not below half of at rest (%.2f mm)\n", answer, at_rest);
            return 1;
        }
        return 0;
    } catch (const physreg::Error& e) {
        std::fprintf(stderr, "example: %s\n", e.what());
        return 1;
    }
}
