// SPDX-License-Identifier: GPL-3.0-or-later
#include "tool_placement.hpp"

#include <cerrno>
#include <cstring>
#include <omp.h>

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/figures/slice_figure.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/phantom/partial_surface.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <string_view>
#include <chrono>
#include <exception>
#include <cmath>
#include <fstream>
#include <numeric>

namespace physreg::detail {

// The label of the voxel nearest to `x`, or nothing outside the image.
std::optional<std::uint16_t> label_at(const LabelVolume& labels, const Vec3& x)
{
    const auto& g = labels.geometry;
    const Vec3 index = g.physical_to_index(x);
    std::int64_t ijk[3];
    for (int a = 0; a < 3; ++a) {
        ijk[a] = std::lround(index[a]);
        if (ijk[a] < 0 || ijk[a] >= g.size[a]) return std::nullopt;
    }
    return labels.at(ijk[0], ijk[1], ijk[2]);
}

// Length (mm) of the segment start + t·d, t ∈ [0, length], inside voxels satisfying `predicate`.
double length_inside(const LabelVolume& labels, const Vec3& start, const Vec3& d, double length,
                     const std::function<bool(std::int32_t)>& predicate)
{
    const double step = 0.5 * labels.geometry.spacing.minCoeff();
    double inside = 0.0;
    for (double t = 0; t <= length; t += step) {
        const auto label = label_at(labels, start + t * d);
        if (label && predicate(*label)) inside += step;
    }
    return inside;
}

// Whether a voxel satisfying `predicate` lies on the segment start + t·d, t ∈ [0, length] (half-voxel steps).
bool line_hits(const LabelVolume& labels, const Vec3& start, const Vec3& d, double length,
               const std::function<bool(std::int32_t)>& predicate)
{
    const double step = 0.5 * labels.geometry.spacing.minCoeff();
    for (double t = 0; t <= length; t += step) {
        const auto label = label_at(labels, start + t * d);
        if (label && predicate(*label)) return true;
    }
    return false;
}

namespace {

// Distance along start + t·d to the first voxel satisfying `predicate` (half-voxel steps), or -1.
double first_hit(const LabelVolume& labels, const Vec3& start, const Vec3& d, double length, const std::function<bool(std::int32_t)>& predicate)
{
    const double step = 0.5 * labels.geometry.spacing.minCoeff();
    for (double t = 0; t <= length; t += step) {
        const auto label = label_at(labels, start + t * d);
        if (label && predicate(*label)) return t;
    }
    return -1.0;
}

// Whether bone lies under the skin patch a tool on the column (x, z) presses: within `reach` of the
// column, less than `below_mm` under the body's surface. The bone's surface is held in the ground
// truth, so a tool on it meets nodes that cannot move and the contact has no solution (the real
// CIRS CT's ribs come within 1 mm of the skin next to the liver).
bool bone_under_patch(const Prepared& p, double x, double z, double start_y, double length, double reach, double below_mm)
{
    if (p.roles.bone.empty()) return false;
    const auto body = [](std::int32_t l) { return l != 0; };
    const auto bone = [&](std::int32_t l) { return p.roles.bone.count(l) > 0; };
    // Lines about 3 mm apart over the disc: a rib is 10–15 mm wide.
    const int rings = std::max(1, static_cast<int>(std::ceil(reach / 3.0)));
    for (int ring = 0; ring <= rings; ++ring) {
        const double r = reach * ring / rings;
        const int around = std::max(1, static_cast<int>(std::ceil(2 * M_PI * r / 3.0)));
        for (int a = 0; a < around; ++a) {
            const double angle = 2 * M_PI * a / around;
            const Vec3 start(x + r * std::cos(angle), start_y, z + r * std::sin(angle));
            const double skin = first_hit(p.labels, start, Vec3::UnitY(), length, body);
            if (skin < 0) continue;
            const double hit = first_hit(p.labels, start + skin * Vec3::UnitY(), Vec3::UnitY(), below_mm, bone);
            if (hit >= 0) return true;
        }
    }
    return false;
}


} // namespace

std::vector<CompressionSpec> default_compressions(const Prepared& p, const PhantomSpec& spec, const Vec3& lo, const Vec3& hi,
                                                  double image_length, bool through_gel)
{
    // Five positions over the liver, as fractions of its x (right→left) and z (inferior→superior) extent.
    const std::pair<double, double> pattern[] = {{0.45, 0.5}, {0.25, 0.45}, {0.62, 0.55}, {0.4, 0.25}, {0.55, 0.75}};
    std::vector<CompressionSpec> out;
    const Vec3 start_y(0, lo.y() - 0.5 * image_length, 0);
    // One compression per depth, at the first positions A, B, … (at most five).
    const int count = static_cast<int>(std::min<std::size_t>(5, spec.depths_mm.size()));
    for (int c = 0; c < count; ++c) {
        CompressionSpec s;
        s.name = std::string(1, static_cast<char>('A' + c));
        s.tool = spec.tool;
        s.depth_mm = spec.depths_mm[static_cast<std::size_t>(c)];
        const double x0 = lo.x() + pattern[c].first * (hi.x() - lo.x()), z0 = lo.z() + pattern[c].second * (hi.z() - lo.z());
        // Nearest column (in 2 mm rings) through the liver. A tool pressing the liver itself needs
        // liver well beyond its depth; one pressing the gel above it, a liver worth aiming at.
        const double required = through_gel ? 30.0 : std::max(30.0, 2.5 * s.depth_mm);
        const double reach = (s.tool.shape == IndenterShape::box ? s.tool.half_extents_mm.norm() : s.tool.radius_mm) +
                             0.5 * spec.ground_truth_mesh.body_cell_mm;
        int bone_columns = 0;
        bool found = false;
        for (double r = 0; r <= 60 && !found; r += 2)
            for (int a = 0; a < std::max(1, static_cast<int>(std::ceil(2 * M_PI * r / 2))) && !found; ++a) {
                const double angle = r == 0 ? 0 : 2 * M_PI * a / std::ceil(2 * M_PI * r / 2);
                const double x = x0 + r * std::cos(angle), z = z0 + r * std::sin(angle);
                // A column through enough liver that the depth stays well inside it.
                const double thickness = length_inside(p.labels, Vec3(x, start_y.y(), z), Vec3::UnitY(), 2 * image_length,
                                                       [&](std::int32_t l) { return p.roles.is_liver_tissue(l); });
                if (thickness < required) continue;
                // Through the gel: the tool's patch (its radius and half a ground-truth body cell
                // around it) must press tissue, not bone near the skin.
                if (through_gel && bone_under_patch(p, x, z, start_y.y(), 2 * image_length, reach, s.depth_mm + 10.0)) {
                    ++bone_columns;
                    continue;
                }
                s.x_mm = x;
                s.z_mm = z;
                found = true;
            }
        if (!found)
            fail("compression {}: no column through ≥ {:.0f} mm of liver within 60 mm of x = {:.1f}, z = {:.1f} mm{}", s.name, required, x0, z0,
                 bone_columns ? fmt::format(" whose tool patch is free of bone ({} columns had bone within {:.0f} mm of the skin)",
                                            bone_columns, s.depth_mm + 10.0)
                              : std::string());
        out.push_back(s);
    }
    return out;
}

Indenter make_indenter(const CompressionSpec& c, const Vec3& start, const Vec3& end)
{
    Indenter tool;
    tool.name = "tool_" + c.name;
    tool.shape = c.tool.shape;
    tool.radius_mm = c.tool.radius_mm;
    tool.axis = c.tool.axis.normalized();
    tool.half_extents_mm = c.tool.half_extents_mm;
    tool.path = {start, end};
    return tool;
}

CompressionSpec push_compression(const Prepared& p, const PhantomSpec& spec, const Vec3& lo, const Vec3& hi, double image_length)
{
    CompressionSpec c;
    c.name = "push";
    c.depth_mm = spec.push_depth_mm;
    c.tool.radius_mm = spec.push_tool_radius_mm;
    const Vec3 start_y(0, lo.y() - 0.5 * image_length, 0);
    double best = 0.0;
    for (double x = lo.x() + 0.1 * (hi.x() - lo.x()); x <= lo.x() + 0.45 * (hi.x() - lo.x()); x += 2.0)
        for (double z = lo.z() + 0.25 * (hi.z() - lo.z()); z <= lo.z() + 0.75 * (hi.z() - lo.z()); z += 2.0) {
            const double thickness = length_inside(p.labels, Vec3(x, start_y.y(), z), Vec3::UnitY(), 2 * image_length,
                                                   [&](std::int32_t l) { return p.roles.is_liver_tissue(l); });
            if (thickness > best) best = thickness, c.x_mm = x, c.z_mm = z;
        }
    if (c.depth_mm > 0.6 * best)
        fail("phantom: --push-depth {} mm: the right lobe is at most {:.0f} mm thick, so the push can go at most {:.0f} mm (60 %)", c.depth_mm, best,
             0.6 * best);
    return c;
}


} // namespace physreg::detail
