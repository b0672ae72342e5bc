// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/dataset.hpp"

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

namespace physreg {
namespace fs = std::filesystem;
using nlohmann::json;

MaterialSet parse_material_set(const std::string& text)
{
    if (text == "paper000") return MaterialSet::paper000;
    if (text == "healthy") return MaterialSet::healthy;
    if (text == "cirrhotic") return MaterialSet::cirrhotic;
    fail("unknown material set '{}' (paper000, healthy, cirrhotic)", text);
}

std::string to_string(MaterialSet set)
{
    switch (set) {
    case MaterialSet::paper000: return "paper000";
    case MaterialSet::healthy: return "healthy";
    case MaterialSet::cirrhotic: return "cirrhotic";
    }
    return "?";
}

TissueTable phantom_tissue_table(MaterialSet set, const LabelRoles& roles, const std::set<std::int32_t>& present)
{
    double parenchyma = 2e5, nu = 0.49, vessel = 1e6, vessel_nu = 0.49, lesion = 5e6;
    if (set != MaterialSet::paper000) {
        parenchyma = set == MaterialSet::healthy ? 3.5e3 : 3.0e4;
        nu = 0.45;
        vessel = 6.2e5;
        vessel_nu = 0.4;
        lesion = 10 * parenchyma;
    }
    TissueTable table;
    auto add = [&](const std::set<std::int32_t>& labels, const std::string& name, double e, double v) {
        int n = 0;
        for (const auto label : labels) {
            if (!present.count(label)) continue;
            table.tissues.push_back({label, n++ == 0 ? name : fmt::format("{}_{}", name, label), e, v, 1000.0});
        }
    };
    add(roles.liver, "parenchyma", parenchyma, nu);
    add(roles.lesion, "lesion", lesion, nu);
    add(roles.vessel, "vessel", vessel, vessel_nu);
    add(roles.kidney, "kidney", 2.5 * parenchyma, nu);
    for (const auto label : present)
        if (label != 0 && !table.find(label)) table.ignored_labels.insert(label);
    table.validate("phantom materials");
    return table;
}

PhantomSpec PhantomSpec::preset_spec(const std::string& name)
{
    PhantomSpec spec;
    spec.preset = name;
    // A 60 mm ball (a fist-sized probe): pressed 25 mm into the gel, a 25 mm one would sink two
    // radii deep and fold the skin over itself, and a 40 mm one moved the landmarks 4.0 mm on average.
    spec.tool.radius_mm = 30.0;
    if (name == "cirs057a") return spec;
    if (name == "small") {
        spec.voxel_mm = 4.0;
        spec.ground_truth_mesh.organ_cell_mm = 7.0;
        spec.ground_truth_mesh.kidney_cell_mm = 10.0;
        spec.ground_truth_mesh.body_cell_mm = 18.0;
        spec.ground_truth_mesh.facet_mm = 5.0;
        spec.ground_truth_mesh.facet_distance_mm = 1.5;
        spec.load_step_mm = 6.0;
        spec.depths_mm = {12, 15, 12, 10, 12};
        spec.tool.radius_mm = 15.0;
        spec.surface_percentages = {50, 10};
        return spec;
    }
    fail("unknown preset '{}' (cirs057a, small, or give a label map with --from-labels)", name);
}

void PhantomSpec::validate() const
{
    if (preset == "from-labels" && labels_file.empty()) fail("phantom: from-labels needs a label map");
    if (preset != "from-labels" && preset != "cirs057a" && preset != "small") fail("phantom: unknown preset '{}'", preset);
    if (!(voxel_mm >= 0.5 && voxel_mm <= 6.0)) fail("phantom: --resolution {} mm outside 0.5 … 6 mm", voxel_mm);
    if (seed < 1 || seed > 4294967295ull) fail("phantom: --seed {} outside 1 … 4294967295", seed);
    ground_truth_mesh.validate();
    if (!(load_step_mm > 0.0 && load_step_mm <= 20.0)) fail("phantom: load step {} mm outside (0, 20]", load_step_mm);
    roles.validate("phantom label roles");
    for (const auto& c : compressions) {
        if (!(c.depth_mm > 0.0 && c.depth_mm <= 60.0)) fail("phantom: compression {}: depth {} mm outside (0, 60]", c.name, c.depth_mm);
        if (!std::isfinite(c.x_mm) || !std::isfinite(c.z_mm)) fail("phantom: compression {}: position is not finite", c.name);
        if (!(c.direction.norm() > 0.0) || !c.direction.allFinite()) fail("phantom: compression {}: direction must be a non-zero vector", c.name);
    }
    if (compressions.empty() && depths_mm.size() > 5)
        fail("phantom: {} depths given; the default compressions take 1 to 5 (A, B, … in order)", depths_mm.size());
    // No compression at all (--depths none) is for studies of the organs' own states: one of them must remain.
    if (compressions.empty() && depths_mm.empty() && !(push_depth_mm > 0) && insufflation_pa && !(*insufflation_pa > 0))
        fail("phantom: no compression (--depths none), no insufflation and no push: the dataset would have no deformed state");
    for (const double d : depths_mm)
        if (!(d > 0.0 && d <= 60.0)) fail("phantom: depth {} mm outside (0, 60]", d);
    if (!(tool.radius_mm > 0.0) || !std::isfinite(tool.radius_mm)) fail("phantom: tool radius {} mm must be > 0", tool.radius_mm);
    if (insufflation_pa && (!(*insufflation_pa >= 0.0) || !std::isfinite(*insufflation_pa)))
        fail("phantom: insufflation pressure {} Pa must be ≥ 0", *insufflation_pa);
    if (!(landmark_noise_mm >= 0.0 && landmark_noise_mm <= 10.0)) fail("phantom: landmark noise {} mm outside [0, 10]", landmark_noise_mm);
    if (!(surface_noise_mm >= 0.0 && surface_noise_mm <= 10.0)) fail("phantom: surface noise {} mm outside [0, 10]", surface_noise_mm);
    for (const int p : surface_percentages)
        if (p <= 0 || p > 100) fail("phantom: surface percentage {} outside 1 … 100", p);
    if (!(push_depth_mm >= 0.0 && push_depth_mm <= 80.0)) fail("phantom: --push-depth {} mm outside [0, 80]", push_depth_mm);
    if (!(push_tool_radius_mm >= 2.0 && push_tool_radius_mm <= 50.0)) fail("phantom: --push-tool-radius {} mm outside [2, 50]", push_tool_radius_mm);
    if (push_cloud_points < 3 || push_cloud_points > 1000000) fail("phantom: --push-points {} outside 3 … 1000000", push_cloud_points);
    if (!(push_cloud_coverage > 0.0 && push_cloud_coverage <= 1.0)) fail("phantom: push cloud coverage {} outside (0, 1]", push_cloud_coverage);
}

namespace {

constexpr int format_version = phantom_dataset_format_version;

std::uint64_t mix_seed(std::uint64_t seed, const std::string& what)
{
    std::uint64_t h = seed ^ 0x9E3779B97F4A7C15ull;
    for (const unsigned char c : what) h = (h ^ c) * 0x100000001B3ull;
    return h;
}

struct Prepared {
    LabelVolume labels;
    LabelRoles roles;
    std::string source;
};

Prepared prepare_labels(const PhantomSpec& spec)
{
    Prepared p;
    if (spec.preset == "from-labels") {
        p.labels = read_label_volume(spec.labels_file);
        p.roles = spec.roles;
        p.source = spec.labels_file.string();
        if (!spec.vessel_mask.empty()) {
            const LabelVolume mask = read_label_volume(spec.vessel_mask);
            if (mask.geometry.size != p.labels.geometry.size || (mask.geometry.origin - p.labels.geometry.origin).norm() > 1e-3 ||
                (mask.geometry.spacing - p.labels.geometry.spacing).norm() > 1e-6)
                fail("vessel mask '{}': its grid differs from the label map '{}'", spec.vessel_mask.string(), spec.labels_file.string());
            std::int32_t vessel_label = p.roles.vessel.empty() ? 0 : *p.roles.vessel.begin();
            if (vessel_label == 0) {
                vessel_label = 1 + *std::max_element(p.labels.labels.begin(), p.labels.labels.end());
                p.roles.vessel.insert(vessel_label);
            }
            std::int64_t changed = 0;
            for (std::size_t v = 0; v < mask.labels.size(); ++v)
                if (mask.labels[v] != 0 && p.roles.liver.count(p.labels.labels[v])) {
                    p.labels.labels[v] = static_cast<std::uint16_t>(vessel_label);
                    ++changed;
                }
            logger()->info("vessel mask '{}': {} voxels inside the liver became vessel (label {})", spec.vessel_mask.string(), changed, vessel_label);
        }
    } else {
        p.labels = make_cirs057a_phantom(spec.voxel_mm);
        p.roles = phantom_label_roles();
        p.source = "built-in preset " + spec.preset;
    }
    const auto counts = count_labels(p.labels);
    bool has_liver = false;
    for (const auto label : p.roles.liver) has_liver |= counts.count(label) > 0;
    if (!has_liver) {
        std::vector<std::int32_t> present;
        for (const auto& [label, n] : counts)
            if (label != 0) present.push_back(label);
        fail("label map '{}': no liver label (liver labels looked for: {}; labels present: {}); give --label-roles",
             p.source, fmt::join(p.roles.liver, ","), fmt::join(present, ","));
    }
    return p;
}

// The ground truth: materials drawn from the seed, the body model for the compressions, the organs
// alone for the insufflation (ground_truth.hpp).
struct GroundTruth {
    TissueTable tissues;
    json material_ranges;
    GroundTruthModel body;
    std::optional<GroundTruthModel> organs; ///< absent when the body model is the organs already
    const GroundTruthModel& insufflation_model() const { return organs ? *organs : body; }
};

GroundTruth build_ground_truth(const Prepared& p, const PhantomSpec& spec)
{
    GroundTruth gt;
    std::set<std::int32_t> present;
    for (const auto& [label, n] : count_labels(p.labels)) present.insert(label);
    LabelRoles roles = p.roles;
    if (!spec.simulate_body) roles.body.clear(), roles.bone.clear(); // the gel stays at rest, nothing holds it
    gt.tissues = draw_ground_truth_tissues(spec.materials, roles, present, mix_seed(spec.seed, "materials"), gt.material_ranges);
    gt.body = build_body_model(p.labels, roles, gt.tissues, spec.ground_truth_mesh, static_cast<unsigned>(spec.seed), spec.organ_support);
    if (gt.body.name == "body") gt.organs = build_organ_model(gt.body, p.roles, gt.tissues, spec.organ_support);
    return gt;
}

Vec3 liver_centroid(const Prepared& p, Vec3& lo, Vec3& hi)
{
    const auto& g = p.labels.geometry;
    Vec3 sum = Vec3::Zero();
    double n = 0;
    lo = Vec3::Constant(1e300);
    hi = Vec3::Constant(-1e300);
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i)
                if (p.roles.is_liver_tissue(p.labels.at(i, j, k))) {
                    const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                    sum += x;
                    n += 1;
                    lo = lo.cwiseMin(x);
                    hi = hi.cwiseMax(x);
                }
    return sum / n;
}

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

struct SolvedState {
    std::vector<double> u;
    GroundTruthSolve solve;
    std::optional<Indenter> tool;
    CompressionSpec compression;
    double pressure_pa = 0.0;
    double requested_tool_scale = 1.0; ///< the tool actually used ÷ the one asked for (> 1: adapted)
    std::string adaptation;            ///< why the tool was enlarged, or ""
};

/// One attempt with the tool as given. A tool that slips between the ground truth's surface nodes
/// (whole cells end inside it) is reported in `slipped`, not as an error: the caller may retry.
SolvedState solve_compression_once(const GroundTruthModel& m, const PhantomSpec& spec, const Prepared& p, const CompressionSpec& c,
                                   std::string& slipped)
{
    const Vec3 d = c.direction.normalized();
    const auto [lo, hi] = p.labels.geometry.physical_box();
    const double length = (hi - lo).norm();
    // The line enters through the image's anterior (start of the pressing direction) side.
    const Vec3 centre_line(c.x_mm, 0.5 * (lo.y() + hi.y()), c.z_mm);
    const Vec3 start = centre_line - length * d;
    if (!line_hits(p.labels, start, d, 2 * length, [](std::int32_t l) { return l != 0; }))
        fail("compression {}: the tool line x = {:.1f} mm, z = {:.1f} mm misses the phantom's body (outside the body)", c.name, c.x_mm, c.z_mm);
    {
        // The tissue the tool presses on along its line: a depth near that thickness would drive the
        // tool through it.
        const double thickness = length_inside(p.labels, start, d, 2 * length, [&](std::int32_t l) { return m.labels.count(l) > 0; });
        if (c.depth_mm > 0.6 * thickness)
            fail("compression {}: depth {:.1f} mm exceeds 60 % of the simulated tissue's thickness along the tool's line ({:.1f} mm at "
                 "x = {:.1f}, z = {:.1f} mm)", c.name, c.depth_mm, thickness, c.x_mm, c.z_mm);
    }
    // Node-to-surface contact holds nodes: the tool must span several surface facets.
    const double width = c.tool.shape == IndenterShape::box ? 2.0 * c.tool.half_extents_mm.minCoeff() : 2.0 * c.tool.radius_mm;
    if (width < 2.0 * spec.ground_truth_mesh.facet_mm)
        fail("compression {}: the tool ({:.1f} mm across) is narrower than two surface facets of the ground truth ({:.1f} mm); "
             "use a larger --tool-radius", c.name, width, 2.0 * spec.ground_truth_mesh.facet_mm);
    const double reach = c.tool.shape == IndenterShape::box ? c.tool.half_extents_mm.norm() : c.tool.radius_mm;
    Indenter probe = make_indenter(c, start, start + 3 * length * d);
    probe.validate();
    // First contact: the smallest travel at which a surface node is inside the tool.
    std::vector<Vec3> candidates;
    for (const auto n : m.model->surface_nodes()) {
        const Vec3& x = m.mesh.nodes[static_cast<std::size_t>(n)];
        const Vec3 r = x - start;
        if ((r - r.dot(d) * d).norm() <= reach + 1.0 || c.tool.shape == IndenterShape::cylinder) candidates.push_back(x);
    }
    auto touches = [&](double t) {
        Indenter tool = make_indenter(c, start + t * d, start + t * d);
        Vec3 surface, normal;
        for (const auto& x : candidates)
            if (tool.push_out(x, 0.0, surface, normal)) return true;
        return false;
    };
    double t_hit = -1;
    for (double t = 0; t <= 3 * length; t += 0.5)
        if (touches(t)) {
            t_hit = t;
            break;
        }
    if (t_hit < 0) fail("compression {}: the tool along x = {:.1f} mm, z = {:.1f} mm never touches the {}", c.name, c.x_mm, c.z_mm, m.name);
    double a = std::max(0.0, t_hit - 0.5), b = t_hit;
    for (int it = 0; it < 30; ++it) (touches(0.5 * (a + b)) ? b : a) = 0.5 * (a + b);
    const Vec3 contact = start + a * d, end = contact + c.depth_mm * d;
    SolvedState s;
    s.tool = make_indenter(c, contact, end);
    Loads loads;
    loads.indenters.push_back(*s.tool);
    const int steps = std::max(1, static_cast<int>(std::ceil(c.depth_mm / spec.load_step_mm - 1e-9)));
    s.solve = solve_ground_truth_state(m, loads, steps, "compression " + c.name);
    s.u = s.solve.displacement_mm;
    // A tool that slipped between surface nodes swallows whole cells.
    for (std::size_t e = 0; e < m.mesh.cell_count(); ++e) {
        Vec3 centre = Vec3::Zero();
        for (const auto n : m.mesh.cell(e)) {
            const auto q = 3 * static_cast<std::size_t>(n);
            centre += (m.mesh.nodes[static_cast<std::size_t>(n)] + Vec3(s.u[q], s.u[q + 1], s.u[q + 2])) / m.mesh.cell_size();
        }
        Vec3 surface, normal;
        if (s.tool->push_out(centre, 1.0, surface, normal) && (surface - centre).norm() > 0.5 * spec.ground_truth_mesh.facet_mm) {
            slipped = fmt::format("the tool slipped past the surface nodes into the tissue (element {} ends inside it)", e);
            return s;
        }
    }
    s.compression = c;
    return s;
}

/// A compression whose tool adapts: a tool that slips between surface nodes, or whose load folds
/// elements, is enlarged by 25 % (up to 3 times, at most ×1.95) and the compression solved again.
/// The dataset records the tool actually used (the registration reads it) and why it grew, so a
/// study looping over seeds does not stop on a seed whose skin mesh happens to be coarse under the
/// tool (seeds 11 and 12 of the small preset did).
SolvedState solve_compression(const GroundTruthModel& m, const PhantomSpec& spec, const Prepared& p, const CompressionSpec& c)
{
    constexpr int attempts = 4;
    constexpr double growth = 1.25;
    CompressionSpec tried = c;
    double scale = 1.0;
    for (int attempt = 1;; ++attempt) {
        std::string slipped;
        try {
            SolvedState s = solve_compression_once(m, spec, p, tried, slipped);
            if (slipped.empty()) {
                s.requested_tool_scale = scale;
                if (scale > 1.0)
                    s.adaptation = fmt::format("tool enlarged ×{:.3g} after {} failed attempt(s)", scale, attempt - 1);
                return s;
            }
        } catch (const Interrupted&) {
            throw;
        } catch (const Error& e) {
            // Only a failed solve is worth a larger tool (solve_ground_truth_state's errors); a tool
            // outside the body, too deep or too narrow is the caller's mistake, said as asked.
            const bool solve_failed = std::string_view(e.what()).starts_with("ground truth for ");
            if (attempt == attempts || !solve_failed) throw;
            slipped = e.what();
        }
        if (attempt == attempts)
            fail("compression {}: {} even with a tool enlarged ×{:.3g}; use a larger --tool-radius or a smaller depth", c.name, slipped, scale);
        scale *= growth;
        tried.tool.radius_mm = c.tool.radius_mm * scale;
        tried.tool.half_extents_mm = c.tool.half_extents_mm * scale;
        logger()->warn("compression {}: {}; solving it again with a tool {:.0f} % larger", c.name, slipped, 100 * (scale - 1));
    }
}

SolvedState solve_insufflation(const GroundTruth& gt, double pressure_pa)
{
    // Gas pressure on the organs' anterior-facing surface (dead load along the rest normal):
    // N = Pa · 1e-6 · mm².
    const GroundTruthModel& m = gt.insufflation_model();
    Loads loads;
    loads.external_forces_n.assign(3 * m.mesh.node_count(), 0.0);
    for (const auto& f : m.faces) {
        if (f.normal.y() > -0.2) continue;
        const Vec3 force = -pressure_pa * 1e-6 * f.area * f.normal;
        for (int a = 0; a < f.count; ++a)
            for (int k = 0; k < 3; ++k) loads.external_forces_n[3 * static_cast<std::size_t>(f.nodes[a]) + k] += force[k] / f.count;
    }
    SolvedState s;
    s.solve = solve_ground_truth_state(m, loads, 4, "insufflation");
    s.u = s.solve.displacement_mm;
    s.pressure_pa = pressure_pa;
    return s;
}

/// Issue 32's large local push: the column over the right lobe (the liver's right 45 % in x, its
/// middle half in z) through the most liver, pressed posterior. Throws Error when no column is
/// thick enough for the depth (the solve refuses a depth over 60 % of the thickness).
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

json to_json(const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); }

std::string shape_name(IndenterShape s)
{
    switch (s) {
    case IndenterShape::sphere: return "sphere";
    case IndenterShape::cylinder: return "cylinder";
    case IndenterShape::plane: return "plane";
    case IndenterShape::box: return "box";
    }
    return "?";
}

LandmarkSet move_landmarks(const LandmarkSet& rest, const std::vector<NodeEmbedding>& where, const VolumeMesh& mesh,
                           const std::vector<double>& u)
{
    LandmarkSet out = rest;
    for (std::size_t l = 0; l < rest.size(); ++l) {
        const auto d = interpolate_nodal(mesh, where[l], u, 3);
        out[l].position += Vec3(d[0], d[1], d[2]);
    }
    return out;
}

LandmarkSet with_noise(const LandmarkSet& set, double sigma, std::uint64_t seed)
{
    SeededRandom random(seed);
    LandmarkSet out = set;
    for (auto& l : out) l.position += sigma * Vec3(random.normal(), random.normal(), random.normal());
    return out;
}

} // namespace

namespace {

// Paints the tool and its shaft (the tool swept back along the pressing direction) as air.
void paint_tool(LabelVolume& labels, ScalarImage& intensity, const Indenter& tool, const Vec3& direction,
                const std::function<bool(std::int32_t)>& deforming)
{
    const auto& g = labels.geometry;
    const Vec3 tip = tool.position(1.0);
    const double reach = tool.shape == IndenterShape::box ? tool.half_extents_mm.norm() : tool.radius_mm;
    const double step = 0.5 * g.spacing.minCoeff();
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                const Vec3 r = x - tip;
                const double along = r.dot(direction);
                if (along > reach) continue;                       // beyond the tool's tip
                if (tool.shape != IndenterShape::cylinder && (r - along * direction).norm() > reach) continue;
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                if (deforming(labels.labels[v]) || labels.labels[v] == 0) continue;
                // Inside the tool moved back by some travel t ≥ 0?
                bool inside = false;
                Vec3 surface, normal;
                for (double t = 0; t <= std::max(0.0, reach - along) + 2 * reach && !inside; t += step)
                    inside = tool.push_out(x + t * direction, 1.0, surface, normal);
                if (!inside) continue;
                labels.labels[v] = 0;
                intensity.values[v] = 0.f;
            }
}

template <typename Write>
std::string write_file(const fs::path& root, const std::string& relative, Write write)
{
    fs::create_directories((root / relative).parent_path());
    write(root / relative);
    return relative;
}

void write_text(const fs::path& path, const std::string& text)
{
    write_atomically(path, [&](const fs::path& tmp) {
        std::ofstream out(tmp);
        out << text;
        if (!out) fail("cannot write '{}': {}", path.string(), std::strerror(errno));
    });
}

} // namespace

DatasetReport generate_phantom_dataset(const PhantomSpec& spec, const fs::path& directory, bool replace,
                                       const std::function<void(double, const std::string&)>& progress)
{
    spec.validate();
    const auto clock0 = std::chrono::steady_clock::now();
    auto seconds_since = [](auto t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); };
    StagedDirectory staged(directory, replace);
    const fs::path root = staged.path();
    json timings = json::object();
    auto report = [&](double f, const std::string& m) {
        if (progress) progress(f, m);
    };

    report(0.0, "anatomy");
    Prepared p = prepare_labels(spec);
    // Each state's image: the noise-free image warped, then noise of its own (independent scans).
    const ScalarImage intensity = synthesize_clean_mr_intensity(p.labels, p.roles, mix_seed(spec.seed, "intensity"));
    Vec3 liver_lo, liver_hi;
    const Vec3 liver_centre = liver_centroid(p, liver_lo, liver_hi);
    timings["anatomy_s"] = seconds_since(clock0);

    report(0.01, "ground-truth mesh");
    auto t = std::chrono::steady_clock::now();
    GroundTruth gt = build_ground_truth(p, spec);
    const auto is_liver = [&](std::int32_t l) { return p.roles.is_liver_tissue(l); };
    timings["ground_truth_model_s"] = seconds_since(t);
    logger()->info("ground truth: {} model, {} nodes, {} tetrahedra (dihedral angles {:.1f}–{:.1f}°){}", gt.body.name, gt.body.mesh.node_count(),
                   gt.body.mesh.cell_count(), gt.body.quality.min_dihedral_deg, gt.body.quality.max_dihedral_deg,
                   gt.organs ? fmt::format("; organs alone {} tetrahedra", gt.organs->mesh.cell_count()) : std::string());

    report(0.07, "landmarks");
    t = std::chrono::steady_clock::now();
    const LandmarkSet rest_landmarks = pick_landmarks(p.labels, p.roles);
    const auto notch_x = find_margin_notch_x(p.labels, p.roles);
    // Per ground-truth model: where the landmarks sit, and the liver's labelled boundary.
    struct ModelView {
        const GroundTruthModel* model;
        std::vector<NodeEmbedding> landmark_cells;
        BoundarySurface liver_surface;
    };
    const auto view_of = [&](const GroundTruthModel& m) {
        return ModelView{&m, embed_landmarks(m.mesh, rest_landmarks, 1.5 * m.organ_cell_mm, "the ground-truth " + m.name + " mesh"), liver_boundary(m.mesh, is_liver, notch_x)};
    };
    const ModelView body_view = view_of(gt.body);
    const std::optional<ModelView> organ_view = gt.organs ? std::optional<ModelView>(view_of(*gt.organs)) : std::nullopt;
    const ModelView& insufflation_view = organ_view ? *organ_view : body_view;
    timings["landmarks_s"] = seconds_since(t);

    json calculix = {{"run", false}};
    if (spec.calculix_validation && !calculix_available()) {
        calculix["reason"] = "ccx (Debian calculix-ccx) is not installed";
    } else if (spec.calculix_validation) {
        report(0.075, "CalculiX validation");
        t = std::chrono::steady_clock::now();
        std::int32_t gel = -1, inclusion = -1;
        for (const auto& tissue : gt.tissues.tissues) {
            if (p.roles.body.count(tissue.label) && gel < 0) gel = tissue.label;
            if (p.roles.liver.count(tissue.label) && inclusion < 0) inclusion = tissue.label;
        }
        if (gel < 0) gel = inclusion; // organs only: a block of parenchyma
        for (const auto& tissue : gt.tissues.tissues)
            if (gel == inclusion && tissue.label != gel) inclusion = tissue.label;
        // Its files go to a scratch folder inside the staged dataset, removed before the dataset appears.
        const fs::path work = root / ".calculix";
        const CalculixValidation v = validate_ground_truth_against_calculix(gt.tissues, gel, inclusion, work);
        fs::remove_all(work);
        calculix = {{"run", true}, {"relative_rms", v.relative_rms}, {"calculix_peak_displacement_mm", v.peak_mm}, {"case", v.description}};
        logger()->info("ground truth vs CalculiX: RMS difference {:.3f} % of the peak displacement {:.2f} mm", 100 * v.relative_rms, v.peak_mm);
        timings["calculix_validation_s"] = seconds_since(t);
    }

    // The experiment's states.
    std::vector<CompressionSpec> compressions = spec.compressions;
    const auto& g = p.labels.geometry;
    const double image_length = g.spacing.cwiseProduct(Vec3(double(g.size[0]), double(g.size[1]), double(g.size[2]))).norm();
    if (compressions.empty()) compressions = default_compressions(p, spec, liver_lo, liver_hi, image_length, gt.body.name == "body");
    double parenchyma_e = 0.0;
    for (const auto& tissue : gt.tissues.tissues)
        if (p.roles.liver.count(tissue.label)) parenchyma_e = std::max(parenchyma_e, tissue.young_modulus_pa);
    const double pressure = spec.insufflation_pa.value_or(0.03 * parenchyma_e);

    json manifest;
    manifest["format"] = "physreg-phantom-dataset";
    manifest["format_version"] = format_version;
    manifest["generator"] = {{"name", "physreg"}, {"version", VERSION}, {"seed", spec.seed}, {"preset", spec.preset},
                             {"source", spec.preset == "from-labels" ? fs::absolute(spec.labels_file).lexically_normal().string() : p.source}};
    manifest["units"] = {{"length", "mm"}, {"displacement", "mm"}, {"young_modulus", "Pa"}, {"pressure", "Pa"},
                         {"force", "N"}, {"intensity", "arbitrary (MR-like)"}};
    manifest["coordinate_system"] = "LPS: ITK physical space (x to the patient's left, y posterior, z superior); 3D Slicer shows RAS";
    json roles;
    for (const auto& [name, set] : std::vector<std::pair<std::string, const std::set<std::int32_t>*>>{
             {"body", &p.roles.body}, {"liver", &p.roles.liver}, {"lesion", &p.roles.lesion},
             {"vessel", &p.roles.vessel}, {"bone", &p.roles.bone}, {"kidney", &p.roles.kidney}})
        roles[name] = *set;
    manifest["label_roles"] = roles;
    manifest["material_set"] = to_string(spec.materials);
    // The ground truth's materials: for reports only — no registration command reads them.
    json tissues = json::array();
    for (const auto& tissue : gt.tissues.tissues) {
        const ElasticMaterial m = material_from_tissue(tissue);
        tissues.push_back({{"label", tissue.label}, {"name", tissue.name}, {"young_modulus_pa", tissue.young_modulus_pa},
                           {"poisson_ratio", tissue.poisson_ratio}, {"density_kg_m3", tissue.density_kg_m3},
                           {"mooney_rivlin_c10_pa", (0.5 * m.mu_mpa - m.c01_mpa) * 1e6}, {"mooney_rivlin_c01_pa", m.c01_mpa * 1e6},
                           {"mooney_rivlin_d1_per_pa", 2.0 / (m.kappa_mpa * 1e6)}});
    }
    write_tissue_table(root / "ground_truth_tissues.yaml", gt.tissues);
    manifest["tissues_file"] = "ground_truth_tissues.yaml";
    const auto describe = [&](const GroundTruthModel& m) {
        const auto& q = m.quality;
        return json{{"nodes", m.mesh.node_count()}, {"elements", m.mesh.cell_count()}, {"support", m.support_description},
                    {"quality", {{"min_dihedral_deg", q.min_dihedral_deg}, {"max_dihedral_deg", q.max_dihedral_deg},
                                 {"cells_below_10_deg", q.below_10_deg}, {"min_radius_ratio", q.min_radius_ratio},
                                 {"mean_radius_ratio", q.mean_radius_ratio}, {"min_edge_mm", q.min_edge_mm},
                                 {"mean_edge_mm", q.mean_edge_mm}, {"max_edge_mm", q.max_edge_mm}}}};
    };
    const auto& gm = spec.ground_truth_mesh;
    std::vector<std::string> simulated;
    for (const auto& tissue : gt.tissues.tissues) simulated.push_back(p.roles.role_of(tissue.label));
    simulated.erase(std::unique(simulated.begin(), simulated.end()), simulated.end());
    manifest["ground_truth"] = {
        {"note", "a different model from every model physreg registers with (those: uniform one-point hexahedra, Neo-Hookean, "
                 "nu 0.49, liver only, literature moduli); registration commands never read this block"},
        {"simulated_tissues", simulated},
        {"tissues", tissues},
        {"material_ranges", gt.material_ranges},
        {"element", "linear tetrahedra (4 nodes, one Gauss point), conforming to every tissue interface, CGAL Mesh_3"},
        {"meshing", {{"organ_cell_mm", gm.organ_cell_mm}, {"kidney_cell_mm", gm.kidney_cell_mm}, {"body_cell_mm", gm.body_cell_mm},
                     {"facet_size_mm", gm.facet_mm}, {"facet_distance_mm", gm.facet_distance_mm}, {"seed", spec.seed}}},
        {"material_law", "compressible Mooney-Rivlin: C10 (I1bar - 3) + C01 (I2bar - 3) + (J - 1)^2 / D1"},
        {"contact", {{"tool", "rigid, frictionless; augmented Lagrangian on the smooth skin nodes, penetration tolerance " +
                                  fmt::format("{} mm", ground_truth_penetration_tolerance_mm)},
                     {"organs_gel", "tied (shared nodes): the phantom's organs are cast into the gel, which bonds to them"}}},
        {"solver", {{"method", "Newton (exact tangent by automatic differentiation, CHOLMOD), load steps with halving"},
                    {"residual_tolerance", ground_truth_residual_tolerance},
                    {"criterion", "largest free nodal residual / largest internal nodal force"},
                    {"load_step_mm", spec.load_step_mm}}},
        {"models", {{gt.body.name, describe(gt.body)}}},
        {"calculix_validation", calculix}};
    if (gt.organs) manifest["ground_truth"]["models"]["organs"] = describe(*gt.organs);
    manifest["landmarks"] = {{"count", rest_landmarks.size()},
                             {"surface", std::count_if(rest_landmarks.begin(), rest_landmarks.end(), [](const Landmark& l) { return l.type == LandmarkType::surface; })},
                             {"noise_sigma_mm", spec.landmark_noise_mm},
                             {"picking", "automatic from the rest labels (tips, ridges, notch; lesion poles; vessel bifurcations)"}};
    manifest["partial_surfaces"] = {{"percentages", spec.surface_percentages}, {"noise_sigma_mm", spec.surface_noise_mm},
                                    {"camera_view_direction", to_json(Vec3::UnitY())},
                                    {"labels", {{"0", "surface"}, {"1", "umbilical notch"}, {"2", "anterior margin"}}}};

    const double fill_intensity = [&] {
        double sum = 0;
        std::int64_t n = 0;
        for (std::size_t v = 0; v < p.labels.labels.size(); ++v)
            if (p.roles.body.count(p.labels.labels[v])) sum += intensity.values[v], ++n;
        return n ? sum / static_cast<double>(n) : 0.0;
    }();
    const double air_intensity = [&] {
        double sum = 0;
        std::int64_t n = 0;
        for (std::size_t v = 0; v < p.labels.labels.size(); ++v)
            if (p.labels.labels[v] == 0) sum += intensity.values[v], ++n;
        return n ? sum / static_cast<double>(n) : 0.0;
    }();
    const std::uint16_t body_label = p.roles.body.empty() ? 0 : static_cast<std::uint16_t>(*p.roles.body.begin());
    const double extension_mm = 1.5 * spec.ground_truth_mesh.facet_mm;

    json states = json::array();
    int state_index = 0;
    // Progress weighted by measured cost (small preset, Release and ASan): preparation ≈ 10 %, the
    // compressions' Newton solves ≈ 70 %, writing the states' images ≈ 15 %, insufflation ≈ 5 %.
    // During the solves the load steps post their own notes (heartbeat lines every ≤ 30 s).
    constexpr double prepared = 0.10, solved_all = 0.82, written_all = 0.95;
    const int written_states = 1 + static_cast<int>(compressions.size());
    const auto writing_fraction = [&](int index) {
        return index == 0 ? prepared : solved_all + (written_all - solved_all) * (index - 1) / std::max(1, written_states - 1);
    };
    auto write_state = [&](const std::string& name, const std::string& kind, const SolvedState* solved, const ModelView& view) {
        const VolumeMesh& mesh = view.model->mesh;
        const auto deforming = [&](std::int32_t l) { return view.model->labels.count(l) > 0; };
        // Voxels a deforming tissue leaves: gel when the gel stays, air when the gel moves too.
        const bool gel_moves = deforming(body_label);
        const std::uint16_t fill_label = gel_moves ? 0 : body_label;
        const double f0 = state_index < written_states ? writing_fraction(state_index) : written_all;
        const std::string dir = name == "rest" ? "rest" : "states/" + name;
        fs::create_directories(root / dir);
        json s;
        s["name"] = name;
        s["kind"] = kind;
        json files;
        const std::vector<double> zero(3 * mesh.node_count(), 0.0);
        const std::vector<double>& u = solved ? solved->u : zero;
        LabelVolume labels = p.labels;
        ScalarImage image = intensity;
        if (solved) {
            report(f0, name + ": images");
            const InverseMap map = rasterize_inverse_map(mesh, u, g, extension_mm);
            labels = warp_labels(p.labels, map, deforming, fill_label);
            image = warp_intensity(intensity, p.labels, labels, map, deforming, static_cast<float>(gel_moves ? air_intensity : fill_intensity));
            if (solved->tool) paint_tool(labels, image, *solved->tool, solved->compression.direction.normalized(), deforming);
            files["inverse_displacement"] = write_file(root, dir + "/inverse_displacement.nii.gz",
                                                       [&](const fs::path& f) { write_displacement_field(f, map.field); });
            const SampledField forward = sample_displacement_field(mesh, u, g);
            files["displacement"] = write_file(root, dir + "/displacement.nii.gz",
                                               [&](const fs::path& f) { write_displacement_field(f, forward.field); });
        }
        files["labels"] = write_file(root, dir + "/labels.nii.gz", [&](const fs::path& f) { write_label_volume(f, labels); });
        add_mr_noise(image, mix_seed(spec.seed, "intensity/" + name));
        files["intensity"] = write_file(root, dir + "/intensity.nii.gz", [&](const fs::path& f) { write_scalar_image(f, image); });
        MeshData data;
        data.point_data.push_back({"displacement", 3, u});
        files["mesh"] = write_file(root, dir + "/mesh.vtu", [&](const fs::path& f) { write_vtu(f, mesh, data); });
        const LandmarkSet landmarks = solved ? move_landmarks(rest_landmarks, view.landmark_cells, mesh, u) : rest_landmarks;
        files["landmarks"] = write_file(root, dir + "/landmarks.csv", [&](const fs::path& f) { write_landmarks(f, landmarks); });
        files["landmarks_noisy"] = write_file(root, dir + "/landmarks_noisy.csv", [&](const fs::path& f) {
            write_landmarks(f, with_noise(landmarks, spec.landmark_noise_mm, mix_seed(spec.seed, "landmarks/" + name)));
        });
        files["liver_surface"] = write_file(root, dir + "/liver_surface.ply", [&](const fs::path& f) { write_boundary_ply(f, mesh, u, view.liver_surface); });
        if (name == "rest" && spec.preset != "from-labels")
            files["vessel_centrelines"] = write_file(root, dir + "/vessel_centrelines.csv", [&](const fs::path& f) {
                write_vessel_centrelines(f, cirs057a_vessel_centrelines());
            });
        json surfaces = json::object();
        if (solved && kind == "push") {
            // Sparse, unlabelled, over nearly the whole surface: all but the back and what the tool covers.
            const Indenter& tool = *solved->tool;
            double covered = 0.0;
            const auto cloud = sparse_surface_cloud(mesh, u, view.liver_surface, spec.push_cloud_coverage, spec.push_cloud_points,
                                                    [&](const Vec3& x) { Vec3 s, n; return tool.push_out(x, 1.0, s, n); }, spec.surface_noise_mm,
                                                    mix_seed(spec.seed, "surface/" + name), &covered);
            const int percent = static_cast<int>(std::lround(100 * covered));
            const std::string stem = fmt::format("{}/sparse_cloud_{:03d}", dir, percent);
            surfaces[std::to_string(percent)] = {
                {"ply", write_file(root, stem + ".ply", [&](const fs::path& f) { write_point_cloud_ply(f, cloud); })},
                {"csv", write_file(root, stem + ".csv", [&](const fs::path& f) { write_point_cloud_csv(f, cloud); })},
                {"points", cloud.points.size()},
                {"kind", "sparse unlabelled cloud over the surface but its back and the tool's footprint"}};
        } else if (solved) {
            for (const int percent : spec.surface_percentages) {
                const auto cloud = visible_surface_patch(mesh, u, view.liver_surface, percent / 100.0, Vec3::UnitY(), spec.surface_noise_mm,
                                                         mix_seed(spec.seed, fmt::format("surface/{}/{}", name, percent)));
                const std::string stem = fmt::format("{}/partial_surface_{:03d}", dir, percent);
                surfaces[std::to_string(percent)] = {
                    {"ply", write_file(root, stem + ".ply", [&](const fs::path& f) { write_point_cloud_ply(f, cloud); })},
                    {"csv", write_file(root, stem + ".csv", [&](const fs::path& f) { write_point_cloud_csv(f, cloud); })},
                    {"points", cloud.points.size()}};
            }
        }
        s["partial_surfaces"] = surfaces;
        // Picture: through the tool's final position for compressions, the liver's centre otherwise.
        SliceFigureOptions figure;
        figure.centre = liver_centre;
        std::string title = "PHYSREG PHANTOM " + name;
        if (solved && solved->tool) {
            const Vec3 tip = solved->tool->position(1.0);
            figure.centre = Vec3(tip.x(), liver_centre.y(), tip.z());
            title += fmt::format(": {} R {:.1f} MM, DEPTH {:.1f} MM", shape_name(solved->tool->shape), solved->tool->radius_mm, solved->compression.depth_mm);
        } else if (solved) {
            title += fmt::format(": PRESSURE {:.0f} PA", solved->pressure_pa);
        }
        if (solved) title += fmt::format(", MAX DISPL. {:.1f} MM", solved->solve.max_displacement_mm);
        figure.title = title;
        figure.pixels_per_mm = std::clamp(600.0 / (g.spacing.x() * g.size[0]), 0.5, 4.0);
        const Canvas canvas = render_orthogonal_slices(image, labels, p.roles, landmarks, {}, figure);
        files["picture"] = write_file(root, dir + "/slices.png", [&](const fs::path& f) { write_png(f, canvas.image()); });
        s["files"] = files;
        if (solved) {
            s["max_displacement_mm"] = solved->solve.max_displacement_mm;
            s["ground_truth_model"] = view.model->name;
            s["load_steps"] = solved->solve.load_steps;
            s["newton_iterations"] = solved->solve.newton_iterations;
            s["contact_updates"] = solved->solve.contact_updates;
            s["worst_residual_ratio"] = solved->solve.worst_residual_ratio;
            s["max_node_penetration_mm"] = solved->solve.max_penetration_mm;
            if (solved->tool) {
                const auto& c = solved->compression;
                s["tool"] = {{"shape", shape_name(solved->tool->shape)}, {"radius_mm", solved->tool->radius_mm},
                             {"axis", to_json(solved->tool->axis)}, {"half_extents_mm", to_json(solved->tool->half_extents_mm)},
                             {"entry_x_mm", c.x_mm}, {"entry_z_mm", c.z_mm}, {"direction", to_json(c.direction.normalized())},
                             {"contact_position_mm", to_json(solved->tool->path.front())},
                             {"final_position_mm", to_json(solved->tool->path.back())}};
                s["depth_mm"] = c.depth_mm;
                if (!solved->adaptation.empty())
                    s["tool_adapted"] = {{"scale", solved->requested_tool_scale}, {"requested_radius_mm", solved->tool->radius_mm / solved->requested_tool_scale},
                                         {"reason", solved->adaptation}};
            } else {
                s["pressure_pa"] = solved->pressure_pa;
                s["pressure_faces"] = "organ surface faces facing anterior (outward normal y < -0.2), dead load";
            }
        }
        states.push_back(s);
        ++state_index;
    };

    write_state("rest", "rest", nullptr, body_view);
    // The compressions are independent: solved two at a time (each Newton solve is mostly a
    // single-threaded CHOLMOD factorisation and triangular solves, so two solves use the two cores
    // far better than one solve's threaded assembly). Each solve is deterministic, so the files do
    // not depend on the thread count.
    report(prepared + 0.01, fmt::format("solving {} compressions", compressions.size()));
    t = std::chrono::steady_clock::now();
    std::vector<SolvedState> solved_compressions(compressions.size());
    std::vector<std::exception_ptr> failures(compressions.size());
    const int solvers = std::max(1, std::min<int>(omp_get_max_threads(), static_cast<int>(compressions.size())));
    std::size_t finished = 0;
    // Deepest first (more load steps, more Newton iterations): the last solve to start is then a
    // short one and the two cores finish together (cirs057a: 600 s → ≈ 500 s for the five).
    std::vector<long> order(compressions.size());
    std::iota(order.begin(), order.end(), 0L);
    std::stable_sort(order.begin(), order.end(), [&](long a, long b) {
        return compressions[static_cast<std::size_t>(a)].depth_mm > compressions[static_cast<std::size_t>(b)].depth_mm;
    });
#pragma omp parallel for schedule(dynamic, 1) num_threads(solvers)
    for (long k = 0; k < static_cast<long>(compressions.size()); ++k) {
        const long c = order[static_cast<std::size_t>(k)];
        try {
            solved_compressions[static_cast<std::size_t>(c)] = solve_compression(gt.body, spec, p, compressions[static_cast<std::size_t>(c)]);
        } catch (...) {
            failures[static_cast<std::size_t>(c)] = std::current_exception();
        }
        // The bar moves as each compression is solved (it stood still for minutes before).
#pragma omp critical(phantom_progress)
        {
            ++finished;
            report(prepared + 0.01 + (solved_all - prepared - 0.01) * double(finished) / double(compressions.size()),
                   fmt::format("{} of {} compressions solved (last: {})", finished, compressions.size(), compressions[static_cast<std::size_t>(c)].name));
        }
    }
    for (const auto& failure : failures)
        if (failure) std::rethrow_exception(failure);
    timings["solve_compressions_s"] = seconds_since(t);
    for (std::size_t k = 0; k < compressions.size(); ++k) {
        const auto& c = compressions[k];
        const SolvedState& solved = solved_compressions[k];
        report(writing_fraction(state_index), "compression " + c.name + ": images");
        t = std::chrono::steady_clock::now();
        timings["solve_" + c.name + "_s"] = solved.solve.seconds;
        logger()->info("compression {}: depth {} mm on the {}, {} load steps, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm",
                       c.name, c.depth_mm, gt.body.name == "body" ? "skin" : "organ", solved.solve.load_steps, solved.solve.newton_iterations,
                       solved.solve.seconds, solved.solve.max_displacement_mm);
        write_state(c.name, "compression", &solved, body_view);
        timings["state_" + c.name + "_s"] = seconds_since(t);
    }
    if (pressure > 0) {
        report(written_all, "insufflation: solving");
        t = std::chrono::steady_clock::now();
        const SolvedState solved = solve_insufflation(gt, pressure);
        timings["solve_insufflation_s"] = solved.solve.seconds;
        logger()->info("insufflation: {:.0f} Pa on the {} model, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm", pressure,
                       gt.insufflation_model().name, solved.solve.newton_iterations, solved.solve.seconds, solved.solve.max_displacement_mm);
        write_state("insufflation", "insufflation", &solved, insufflation_view);
        timings["state_insufflation_s"] = seconds_since(t);
        std::vector<std::string> organs;
        for (const auto* set : {&p.roles.liver, &p.roles.kidney})
            for (const auto l : *set)
                if (gt.tissues.find(l)) organs.push_back(p.roles.role_of(l));
        organs.erase(std::unique(organs.begin(), organs.end()), organs.end());
        manifest["segmentation_pairs"] = json::array({{{"name", "insufflation"}, {"moving", "rest/labels.nii.gz"},
                                                       {"reference", "states/insufflation/labels.nii.gz"},
                                                       {"deforming_organs", organs},
                                                       {"note", "moving = pre-operative labels, reference = after the pressure load; each organ deforms with its own stiffness and support"}}});
    } else {
        manifest["segmentation_pairs"] = json::array();
    }
    if (spec.push_depth_mm > 0) {
        report(0.97, "large local push: solving");
        t = std::chrono::steady_clock::now();
        const CompressionSpec c = push_compression(p, spec, liver_lo, liver_hi, image_length);
        const SolvedState solved = solve_compression(gt.insufflation_model(), spec, p, c);
        timings["solve_push_s"] = solved.solve.seconds;
        logger()->info("push: {} mm by a {:.0f} mm tool on the {} model, {} Newton iterations, {:.1f} s, max displacement {:.2f} mm", c.depth_mm,
                       2 * solved.tool->radius_mm, gt.insufflation_model().name, solved.solve.newton_iterations, solved.solve.seconds,
                       solved.solve.max_displacement_mm);
        write_state("push", "push", &solved, insufflation_view);
        timings["state_push_s"] = seconds_since(t);
    }
    manifest["states"] = states;
    write_text(root / "manifest.json", manifest.dump(2) + "\n");
    report(1.0, "done");
    staged.commit();
    json summary = manifest;
    summary["output"] = directory.string();
    timings["total_s"] = seconds_since(clock0);
    summary["timings"] = timings;
    return {summary.dump(2)};
}

} // namespace physreg
