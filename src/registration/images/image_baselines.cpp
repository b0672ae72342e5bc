// SPDX-License-Identifier: GPL-3.0-or-later
// Paper 002's baselines: validation and conversion around the ITK translation unit.
#include "physreg/registration/images/image_baselines.hpp"

#include "registration/detail/itk_baselines.hpp"
#include "physreg/core/error.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>

namespace physreg {
namespace {

detail::PlainImage plain(const ScalarImage& in)
{
    detail::PlainImage out;
    for (int a = 0; a < 3; ++a) {
        out.geometry.size[static_cast<std::size_t>(a)] = in.geometry.size[a];
        out.geometry.origin[static_cast<std::size_t>(a)] = in.geometry.origin[a];
        out.geometry.spacing[static_cast<std::size_t>(a)] = in.geometry.spacing[a];
        for (int b = 0; b < 3; ++b) out.geometry.direction[static_cast<std::size_t>(3 * a + b)] = in.geometry.direction(a, b);
    }
    out.values = in.values;
    return out;
}

/// The physical bounding box of an image's voxel centres.
std::pair<Vec3, Vec3> bounds(const ImageGeometry& g)
{
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (int corner = 0; corner < 8; ++corner) {
        const Vec3 index((corner & 1) ? g.size[0] - 1 : 0, (corner & 2) ? g.size[1] - 1 : 0, (corner & 4) ? g.size[2] - 1 : 0);
        const Vec3 p = g.index_to_physical(index);
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    return {lo, hi};
}

} // namespace

BaselineMethod parse_baseline_method(const std::string& text)
{
    if (text == "rigid") return BaselineMethod::rigid;
    if (text == "demons") return BaselineMethod::demons;
    if (text == "bspline") return BaselineMethod::bspline;
    fail("baseline method '{}': use rigid, demons or bspline", text);
}

std::string to_string(BaselineMethod method)
{
    switch (method) {
    case BaselineMethod::rigid: return "rigid";
    case BaselineMethod::demons: return "demons";
    case BaselineMethod::bspline: return "bspline";
    }
    return "?";
}

void BaselineOptions::validate() const
{
    if (rigid_iterations < 1) fail("rigid iterations {} must be ≥ 1", rigid_iterations);
    if (demons_iterations.empty()) fail("demons: at least one level");
    for (int i : demons_iterations)
        if (i < 1) fail("demons iterations {} must be ≥ 1", i);
    if (!(demons_field_sigma_voxels > 0.0)) fail("demons field σ {} voxels must be > 0", demons_field_sigma_voxels);
    if (!(bspline_grid_mm > 0.0)) fail("B-spline grid spacing {} mm must be > 0", bspline_grid_mm);
    if (bspline_iterations < 1) fail("B-spline iterations {} must be ≥ 1", bspline_iterations);
    if (!(bspline_sampling > 0.0 && bspline_sampling <= 1.0)) fail("B-spline metric sampling {} must lie in (0, 1]", bspline_sampling);
}

BaselineResult register_baseline(const ScalarImage& fixed, const ScalarImage& moving, BaselineMethod method, bool labels_mode,
                                 const BaselineOptions& options)
{
    options.validate();
    fixed.geometry.validate("fixed image");
    moving.geometry.validate("moving image");
    const auto [flo, fhi] = bounds(fixed.geometry);
    const auto [mlo, mhi] = bounds(moving.geometry);
    if ((flo.array() > mhi.array()).any() || (mlo.array() > fhi.array()).any())
        fail("the fixed and moving images do not overlap in physical space (fixed [{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] mm, moving "
             "[{:.1f} {:.1f} {:.1f}]–[{:.1f} {:.1f} {:.1f}] mm)", flo[0], flo[1], flo[2], fhi[0], fhi[1], fhi[2], mlo[0], mlo[1], mlo[2], mhi[0], mhi[1], mhi[2]);
    if (fixed.values.size() != static_cast<std::size_t>(fixed.geometry.voxel_count()) ||
        moving.values.size() != static_cast<std::size_t>(moving.geometry.voxel_count()))
        fail("{} registration: an image's values do not match its size", to_string(method));
    const auto t0 = std::chrono::steady_clock::now();
    detail::PlainBaselineOptions o;
    o.method = to_string(method);
    o.labels_mode = labels_mode;
    o.rigid_iterations = options.rigid_iterations;
    o.demons_iterations = options.demons_iterations;
    o.demons_sigma_voxels = options.demons_field_sigma_voxels;
    o.bspline_grid_mm = options.bspline_grid_mm;
    o.bspline_iterations = options.bspline_iterations;
    o.bspline_sampling = options.bspline_sampling;
    o.seed = options.seed;
    o.threads = omp_get_max_threads();
    detail::PlainBaselineResult plain_result = detail::itk_register_baseline(plain(fixed), plain(moving), o);
    BaselineResult r;
    r.fixed_to_moving.geometry = fixed.geometry;
    r.fixed_to_moving.components = std::move(plain_result.field);
    for (const auto& [name, value] : plain_result.figures) r.figures[name] = value;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
}

ScalarImage label_intensity_image(const LabelVolume& labels, const std::vector<std::int32_t>& structures)
{
    ScalarImage raw;
    raw.geometry = labels.geometry;
    raw.values.assign(labels.labels.size(), 0.0f);
    for (std::size_t v = 0; v < labels.labels.size(); ++v) {
        const auto it = std::find(structures.begin(), structures.end(), static_cast<std::int32_t>(labels.labels[v]));
        if (it != structures.end()) raw.values[v] = 100.0f * static_cast<float>(1 + (it - structures.begin()));
    }
    raw.values = detail::itk_smooth(plain(raw), labels.geometry.spacing.minCoeff());
    return raw;
}

} // namespace physreg
