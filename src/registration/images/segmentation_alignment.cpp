// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/images/segmentation_alignment.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/image/distance_map.hpp"
#include "registration/detail/principal_axes.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <set>

namespace physreg {

InitialAlignment parse_initial_alignment(const std::string& text)
{
    if (text == "identity") return InitialAlignment::identity;
    if (text == "centroid") return InitialAlignment::centroid;
    if (text == "rigid") return InitialAlignment::rigid;
    if (text == "translation") return InitialAlignment::translation;
    fail("--initial '{}': use identity, centroid, translation or rigid", text);
}

std::string to_string(InitialAlignment mode)
{
    switch (mode) {
    case InitialAlignment::identity: return "identity";
    case InitialAlignment::centroid: return "centroid";
    case InitialAlignment::rigid: return "rigid";
    case InitialAlignment::translation: return "translation";
    }
    return "?";
}

namespace {

struct StructurePoints {
    std::vector<Vec3> all;      ///< voxel centres (every structure)
    std::vector<std::vector<Vec3>> boundary; ///< per structure: voxels with a 6-neighbour of another label
};

StructurePoints collect(const LabelVolume& v, const std::vector<std::int32_t>& structures, const std::string& which)
{
    StructurePoints p;
    p.boundary.resize(structures.size());
    const auto& g = v.geometry;
    std::vector<std::size_t> counts(structures.size(), 0);
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const std::int32_t label = v.at(i, j, k);
                const auto s = std::find(structures.begin(), structures.end(), label);
                if (s == structures.end()) continue;
                const auto index = static_cast<std::size_t>(s - structures.begin());
                ++counts[index];
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                p.all.push_back(x);
                // Boundary points: the centres of the faces this voxel shares with another label
                // (where the distance maps' zero level lies); faces on the image border are no
                // boundary of the organ, only of the field of view.
                const std::int64_t n[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k}, {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
                for (const auto& q : n) {
                    if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= g.size[0] || q[1] >= g.size[1] || q[2] >= g.size[2]) continue;
                    if (v.at(q[0], q[1], q[2]) == label) continue;
                    const Vec3 y = g.index_to_physical(Vec3(double(q[0]), double(q[1]), double(q[2])));
                    p.boundary[index].push_back(0.5 * (x + y));
                }
            }
    for (std::size_t s = 0; s < structures.size(); ++s)
        if (counts[s] == 0) fail("initial alignment: structure {} is empty in the {} segmentation; it cannot be matched", structures[s], which);
        else if (p.boundary[s].empty())
            fail("initial alignment: structure {} fills the {} image (no boundary inside it); it cannot be matched", structures[s], which);
    // At most 4000 boundary points per structure (every n-th): the cost is a mean, not a sum of voxels.
    for (auto& b : p.boundary)
        if (b.size() > 4000) {
            const std::size_t stride = (b.size() + 3999) / 4000;
            std::vector<Vec3> kept;
            for (std::size_t q = 0; q < b.size(); q += stride) kept.push_back(b[q]);
            b.swap(kept);
        }
    return p;
}

// Root mean square of φ over the moving boundary points under (R, t); Gauss–Newton with a
// Levenberg damping from there.
struct Fit {
    Mat3 rotation;
    Vec3 translation;
    double rms = 0.0;
    int iterations = 0;
};

using Maps = std::vector<const SignedDistanceMap*>;
using Boundaries = std::vector<std::vector<Vec3>>;

double rms_distance(const Maps& maps, const Boundaries& moving, const Mat3& r, const Vec3& t)
{
    double sum = 0.0;
    std::size_t n = 0;
    for (std::size_t s = 0; s < maps.size(); ++s)
        for (const auto& x : moving[s]) {
            const double phi = maps[s]->value(r * x + t);
            sum += phi * phi;
            ++n;
        }
    return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(1, n)));
}

/// `rotate` false: the translation alone (the rotation stays r).
Fit refine(const Maps& maps, const Boundaries& moving, Mat3 r, Vec3 t, bool rotate = true)
{
    Fit f{r, t, rms_distance(maps, moving, r, t), 0};
    double lambda = 1e-3;
    for (int it = 0; it < 100; ++it) {
        Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
        Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
        Vec3 centre = Vec3::Zero();
        std::size_t count = 0;
        for (std::size_t s = 0; s < maps.size(); ++s)
            for (const auto& x : moving[s]) centre += f.rotation * x + f.translation, ++count;
        centre /= static_cast<double>(count);
        for (std::size_t s = 0; s < maps.size(); ++s)
            for (const auto& x : moving[s]) {
                const Vec3 y = f.rotation * x + f.translation;
                Vec3 g;
                const double phi = maps[s]->value_and_gradient(y, g);
                Eigen::Matrix<double, 6, 1> row;
                row << (y - centre).cross(g), g;
                a += row * row.transpose();
                b -= row * phi;
            }
        if (!rotate) {
            a.topLeftCorner<3, 3>().setIdentity();
            a.topRightCorner<3, 3>().setZero();
            a.bottomLeftCorner<3, 3>().setZero();
            b.head<3>().setZero();
        }
        bool improved = false;
        for (int tries = 0; tries < 10 && !improved; ++tries) {
            Eigen::Matrix<double, 6, 6> damped = a;
            damped.diagonal() += lambda * (a.diagonal().array() + 1e-9).matrix();
            const Eigen::Matrix<double, 6, 1> step = damped.ldlt().solve(b);
            const Vec3 omega = step.head<3>();
            const Mat3 turn = omega.norm() > 0 ? Mat3(Eigen::AngleAxisd(omega.norm(), omega.normalized())) : Mat3::Identity();
            const Mat3 r1 = turn * f.rotation;
            const Vec3 t1 = turn * (f.translation - centre) + centre + Vec3(step.tail<3>());
            const double rms = rms_distance(maps, moving, r1, t1);
            if (rms < f.rms) {
                const double gain = f.rms - rms;
                f = {r1, t1, rms, it + 1};
                lambda = std::max(1e-6, lambda / 3);
                improved = true;
                if (gain < 1e-4 * std::max(1.0, rms)) return f;
            } else {
                lambda *= 10;
            }
        }
        if (!improved) break;
    }
    return f;
}

double rotation_angle_deg(const Mat3& r) { return Eigen::AngleAxisd(r).angle() * 180.0 / M_PI; }

/// The winning hypothesis: the best plausible one (the first start — centroids — wins near-ties
/// within 5 %: a symmetric shape's axes are a guess, its centroid is not), unless an implausible
/// one fits at most half as far and closer by more than `voxel_mm`. `decision` says why.
std::size_t choose_hypothesis(const std::vector<AlignmentHypothesis>& h, double max_deg, double voxel_mm, std::string* decision)
{
    const auto best_of = [&](bool plausible) {
        std::optional<std::size_t> best;
        for (std::size_t i = 0; i < h.size(); ++i)
            if (h[i].plausible == plausible && (!best || h[i].rms_boundary_distance_mm < 0.95 * h[*best].rms_boundary_distance_mm)) best = i;
        return best;
    };
    const auto near = best_of(true), far = best_of(false);
    if (!near) {
        *decision = fmt::format("no start ended within {:.0f}° of the identity; the best fit ({}, {:.1f}°) is taken", max_deg, h[*far].start,
                                h[*far].rotation_deg);
        return *far;
    }
    const double a = h[*near].rms_boundary_distance_mm;
    if (far) {
        const double b = h[*far].rms_boundary_distance_mm;
        if (b < 0.5 * a && a - b > voxel_mm) {
            *decision = fmt::format("the pose turned {:.1f}° ({}) fits the boundaries at {:.2f} mm against {:.2f} mm for the best within {:.0f}°: "
                                    "less than half, and closer by more than a voxel ({:.2f} mm)", h[*far].rotation_deg, h[*far].start, b, a, max_deg, voxel_mm);
            return *far;
        }
        if (b < a) {
            *decision = fmt::format("kept the best pose within {:.0f}° ({}, {:.1f}°, {:.2f} mm): the pose turned {:.1f}° ({}) fits at {:.2f} mm, "
                                    "not by the margin the data resolve (half the distance and a voxel, {:.2f} mm)", max_deg, h[*near].start,
                                    h[*near].rotation_deg, a, h[*far].rotation_deg, h[*far].start, b, voxel_mm);
            return *near;
        }
    }
    *decision = fmt::format("the best fit ({}, {:.1f}°, {:.2f} mm) lies within {:.0f}° of the identity", h[*near].start, h[*near].rotation_deg, a, max_deg);
    return *near;
}

} // namespace

SegmentationAlignment align_segmentations(const LabelVolume& fixed, const LabelVolume& moving, const std::vector<std::int32_t>& structures,
                                          InitialAlignment mode, double max_plausible_rotation_deg)
{
    if (structures.empty()) fail("initial alignment: no structure to align");
    if (!(max_plausible_rotation_deg > 0 && max_plausible_rotation_deg <= 180))
        fail("initial alignment: the largest plausible rotation must lie in (0, 180] degrees (got {})", max_plausible_rotation_deg);
    SegmentationAlignment out;
    out.mode = mode;
    const StructurePoints f = collect(fixed, structures, "fixed");
    const StructurePoints m = collect(moving, structures, "moving");
    const detail::PrincipalFrame ff = detail::principal_frame(f.all), fm = detail::principal_frame(m.all);
    const Vec3 cf = ff.centre, cm = fm.centre;
    out.centroid_distance_mm = (cf - cm).norm();
    std::vector<std::unique_ptr<SignedDistanceMap>> owned;
    Maps maps;
    for (const auto label : structures) {
        owned.push_back(std::make_unique<SignedDistanceMap>(fixed, std::set<std::int32_t>{label}, "fixed structure " + std::to_string(label)));
        maps.push_back(owned.back().get());
    }
    out.rms_boundary_distance_before_mm = rms_distance(maps, m.boundary, Mat3::Identity(), Vec3::Zero());
    if (mode == InitialAlignment::identity) {
        out.rms_boundary_distance_mm = out.rms_boundary_distance_before_mm;
        out.start = "identity";
        return out;
    }
    out.translation = cf - cm;
    out.start = "centroids";
    if (mode == InitialAlignment::translation) {
        const Fit shift = refine(maps, m.boundary, Mat3::Identity(), cf - cm, false);
        out.translation = shift.translation;
        out.iterations = shift.iterations;
        out.hypotheses.push_back({"translation", shift.rms, 0.0, true});
        out.decision = "the translation that fits the boundaries best, from the centroids (no rotation)";
    }
    if (mode == InitialAlignment::rigid) {
        // Starts: centroids only; principal axes matched (four right-handed sign choices).
        std::vector<std::pair<std::string, Mat3>> starts{{"centroids", Mat3::Identity()}};
        for (int signs = 0; signs < 4; ++signs)
            starts.push_back({"principal axes " + std::to_string(signs), ff.axes * detail::axis_flip(signs) * fm.axes.transpose()});
        std::vector<Fit> fits;
        for (const auto& [name, r0] : starts) {
            fits.push_back(refine(maps, m.boundary, r0, cf - r0 * cm));
            const double angle = rotation_angle_deg(fits.back().rotation);
            out.hypotheses.push_back({name, fits.back().rms, angle, angle <= max_plausible_rotation_deg});
            logger()->debug("initial alignment: start {}: RMS boundary distance {:.3f} mm, rotation {:.1f}° after {} iterations", name,
                            fits.back().rms, angle, fits.back().iterations);
        }
        const double voxel_mm = fixed.geometry.spacing.maxCoeff();
        std::size_t chosen = choose_hypothesis(out.hypotheses, max_plausible_rotation_deg, voxel_mm, &out.decision);
        // Issue 57: the translation alone is a hypothesis too. One structure's outline barely
        // resolves its rotation: on 20 public MR → TRUS gland pairs the rigid fit turned 1–60° (117°
        // once) to gain 0–40 % of the boundary RMS distance, and left the landmarks 7.5 mm off where
        // the translation left 5.2 mm (a deformed outline looks turned). So with one structure a
        // rotation is taken only when it leaves at most half the distance the translation leaves
        // (there it explains more than the deformation does). Two or more structures resolve the
        // turn by their layout (the project's pairs with a lesion, vessels: a true 9° turn gains only
        // 15 % yet is right), and a largest plausible rotation of 180° trusts the best fit alone.
        const Fit shift = refine(maps, m.boundary, Mat3::Identity(), cf - cm, false);
        const double turned_rms = fits[chosen].rms;
        if (structures.size() == 1 && max_plausible_rotation_deg < 180.0 && !(turned_rms < 0.5 * shift.rms)) {
            out.decision = fmt::format("kept the translation ({:.2f} mm): the best rotated pose ({}, {:.1f}°) fits the boundaries at {:.2f} mm, "
                                       "not by the margin the data resolve (half the translation's distance); {}", shift.rms,
                                       out.hypotheses[chosen].start, out.hypotheses[chosen].rotation_deg, turned_rms, out.decision);
            chosen = fits.size();
        } else if (structures.size() == 1) {
            out.decision = fmt::format("the rotation resolves the boundary ({:.2f} mm against {:.2f} mm for the translation alone): {}", turned_rms,
                                       shift.rms, out.decision);
        }
        fits.push_back(shift);
        out.hypotheses.push_back({"translation", shift.rms, 0.0, true});
        const Fit& best = fits[chosen];
        out.start = out.hypotheses[chosen].start;
        // The runner-up: the best fit among the poses that differ from the winner (by more than 5°).
        double runner_rms = std::numeric_limits<double>::infinity();
        for (std::size_t i = 0; i < fits.size(); ++i) {
            const double apart = rotation_angle_deg(fits[i].rotation * best.rotation.transpose());
            if (apart > 5.0 && fits[i].rms < runner_rms) {
                runner_rms = fits[i].rms;
                out.runner_up = out.hypotheses[i].start;
                out.runner_up_margin_mm = fits[i].rms - best.rms;
                out.runner_up_rotation_deg = apart;
            }
        }
        out.rotation = best.rotation;
        out.translation = best.translation;
        out.iterations = best.iterations;
    }
    out.rotation_deg = Eigen::AngleAxisd(out.rotation).angle() * 180.0 / M_PI;
    out.rms_boundary_distance_mm = rms_distance(maps, m.boundary, out.rotation, out.translation);
    return out;
}

SegmentationAlignment align_points_to_maps(const std::vector<const SignedDistanceMap*>& maps, const std::vector<std::vector<Vec3>>& points)
{
    if (maps.size() != points.size()) fail("rigid fit: {} maps for {} point sets", maps.size(), points.size());
    Maps used;
    Boundaries moving;
    for (std::size_t s = 0; s < maps.size(); ++s)
        if (maps[s] && !points[s].empty()) used.push_back(maps[s]), moving.push_back(points[s]);
    if (used.empty()) fail("rigid fit: no structure has both a map and points");
    SegmentationAlignment out;
    out.mode = InitialAlignment::rigid;
    out.start = "identity";
    out.rms_boundary_distance_before_mm = rms_distance(used, moving, Mat3::Identity(), Vec3::Zero());
    const Fit fit = refine(used, moving, Mat3::Identity(), Vec3::Zero());
    out.rotation = fit.rotation;
    out.translation = fit.translation;
    out.iterations = fit.iterations;
    out.rotation_deg = Eigen::AngleAxisd(out.rotation).angle() * 180.0 / M_PI;
    out.rms_boundary_distance_mm = fit.rms;
    return out;
}

} // namespace physreg
