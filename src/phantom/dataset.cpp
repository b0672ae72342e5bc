#include "physreg/phantom/dataset.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/version.hpp"
#include "physreg/field/displacement_sampling.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/figures/slice_figure.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/coarsen.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/phantom/partial_surface.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
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

EquilibriumOptions PhantomSpec::tight_equilibrium()
{
    EquilibriumOptions o;
    o.displacement_tolerance_mm = 1e-3;
    o.residual_tolerance = 1e-4;
    o.max_iterations = 400000;
    return o;
}

PhantomSpec PhantomSpec::preset_spec(const std::string& name)
{
    PhantomSpec spec;
    spec.preset = name;
    if (name == "cirs057a") return spec;
    if (name == "small") {
        spec.voxel_mm = 4.0;
        spec.ground_truth_grid = {37, 27, 12};
        spec.depths_mm = {6, 8, 6, 5, 6};
        spec.tool.radius_mm = 12.0;
        spec.surface_percentages = {50, 10};
        spec.equilibrium.displacement_tolerance_mm = 1e-3;
        return spec;
    }
    fail("unknown preset '{}' (cirs057a, small, or give a label map with --from-labels)", name);
}

void PhantomSpec::validate() const
{
    if (preset == "from-labels" && labels_file.empty()) fail("phantom: from-labels needs a label map");
    if (preset != "from-labels" && preset != "cirs057a" && preset != "small") fail("phantom: unknown preset '{}'", preset);
    if (!(voxel_mm >= 0.5 && voxel_mm <= 6.0)) fail("phantom: --resolution {} mm outside 0.5 … 6 mm", voxel_mm);
    for (int a = 0; a < 3; ++a)
        if (ground_truth_grid[a] < 2 || ground_truth_grid[a] > 2000) fail("phantom: ground-truth grid dimension {} outside 2 … 2000", ground_truth_grid[a]);
    roles.validate("phantom label roles");
    for (const auto& c : compressions) {
        if (!(c.depth_mm > 0.0 && c.depth_mm <= 60.0)) fail("phantom: compression {}: depth {} mm outside (0, 60]", c.name, c.depth_mm);
        if (!std::isfinite(c.x_mm) || !std::isfinite(c.z_mm)) fail("phantom: compression {}: position is not finite", c.name);
        if (!(c.direction.norm() > 0.0) || !c.direction.allFinite()) fail("phantom: compression {}: direction must be a non-zero vector", c.name);
    }
    for (const double d : depths_mm)
        if (!(d > 0.0 && d <= 60.0)) fail("phantom: depth {} mm outside (0, 60]", d);
    if (!(tool.radius_mm > 0.0) || !std::isfinite(tool.radius_mm)) fail("phantom: tool radius {} mm must be > 0", tool.radius_mm);
    if (insufflation_pa && (!(*insufflation_pa >= 0.0) || !std::isfinite(*insufflation_pa)))
        fail("phantom: insufflation pressure {} Pa must be ≥ 0", *insufflation_pa);
    if (!(landmark_noise_mm >= 0.0 && landmark_noise_mm <= 10.0)) fail("phantom: landmark noise {} mm outside [0, 10]", landmark_noise_mm);
    if (!(surface_noise_mm >= 0.0 && surface_noise_mm <= 10.0)) fail("phantom: surface noise {} mm outside [0, 10]", surface_noise_mm);
    for (const int p : surface_percentages)
        if (p <= 0 || p > 100) fail("phantom: surface percentage {} outside 1 … 100", p);
    if (!(tool_speed_per_cell > 0.0 && tool_speed_per_cell <= 1.0)) fail("phantom: tool speed {} cells per iteration outside (0, 1]", tool_speed_per_cell);
    equilibrium.validate();
}

const DatasetState& PhantomDataset::state(const std::string& name) const
{
    for (const auto& s : states)
        if (s.name == name) return s;
    fail("dataset '{}': no state '{}'", directory.string(), name);
}

namespace {

constexpr int format_version = 1;

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

// The ground-truth model: the organs that deform, on a grid finer than the evaluated models'.
struct GroundTruth {
    TissueTable tissues;
    VolumeMesh mesh;
    std::unique_ptr<TledModel> model;
    std::vector<BoundaryFace> faces;
    std::vector<std::int32_t> fixed_nodes, boundary_nodes;
    Vec3 cell_size;
    /// A model on a grid half as fine: its solution, interpolated, starts the fine relaxation.
    std::unique_ptr<GroundTruth> pilot;
    std::vector<NodeEmbedding> nodes_in_pilot;
};

void build_model(GroundTruth& gt, const Prepared& p, const Index3& dims);

GroundTruth build_ground_truth(const Prepared& p, const PhantomSpec& spec)
{
    GroundTruth gt;
    std::set<std::int32_t> present;
    for (const auto& [label, n] : count_labels(p.labels)) present.insert(label);
    gt.tissues = phantom_tissue_table(spec.materials, p.roles, present);
    // Liver extent in voxels per image axis; cells per axis from the physical axis it follows.
    const auto& g = p.labels.geometry;
    Index3 lo{g.size[0], g.size[1], g.size[2]}, hi{-1, -1, -1};
    Index3 mlo = lo, mhi = hi;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto label = p.labels.at(i, j, k);
                const std::int64_t ijk[3] = {i, j, k};
                if (p.roles.is_liver_tissue(label))
                    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], ijk[a]), hi[a] = std::max(hi[a], ijk[a]);
                if (gt.tissues.find(label))
                    for (int a = 0; a < 3; ++a) mlo[a] = std::min(mlo[a], ijk[a]), mhi[a] = std::max(mhi[a], ijk[a]);
            }
    Index3 dims;
    for (int a = 0; a < 3; ++a) {
        int physical = 0;
        for (int q = 1; q < 3; ++q)
            if (std::abs(g.direction(q, a)) > std::abs(g.direction(physical, a))) physical = q;
        const std::int64_t liver_voxels = hi[a] - lo[a] + 1, organ_voxels = mhi[a] - mlo[a] + 1;
        const std::int64_t wanted = spec.ground_truth_grid[physical];
        if (wanted > liver_voxels)
            logger()->warn("ground truth: {} cells wanted along image axis {} but the liver spans {} voxels; using {}",
                           wanted, a, liver_voxels, liver_voxels);
        const double voxels_per_cell = static_cast<double>(liver_voxels) / static_cast<double>(std::min(wanted, liver_voxels));
        dims[a] = std::clamp<std::int64_t>(std::llround(static_cast<double>(organ_voxels) / voxels_per_cell), 1, organ_voxels);
    }
    build_model(gt, p, dims);
    if (gt.mesh.cell_count() <= 20000) return gt; // small enough to relax directly from rest
    gt.pilot = std::make_unique<GroundTruth>();
    gt.pilot->tissues = gt.tissues;
    Index3 pilot_dims;
    for (int a = 0; a < 3; ++a) pilot_dims[a] = std::max<std::int64_t>(2, (dims[a] + 1) / 2);
    build_model(*gt.pilot, p, pilot_dims);
    gt.nodes_in_pilot = embed_in_grid_mesh(gt.pilot->mesh, gt.mesh.nodes);
    return gt;
}

void build_model(GroundTruth& gt, const Prepared& p, const Index3& dims)
{
    MeshingOptions options;
    options.grid_dims = dims;
    options.components = ComponentPolicy::keep_all;
    auto meshed = mesh_label_volume(p.labels, gt.tissues, options, p.source);
    gt.mesh = std::move(meshed.mesh);
    gt.cell_size = gt.mesh.grid->cell_size;
    TledOptions tled;
    gt.model = std::make_unique<TledModel>(gt.mesh, gt.tissues, tled);
    gt.faces = boundary_faces(gt.mesh);
    std::vector<char> fixed(gt.mesh.node_count(), 0), boundary(gt.mesh.node_count(), 0);
    for (const auto& f : gt.faces)
        for (int a = 0; a < f.count; ++a) {
            boundary[static_cast<std::size_t>(f.nodes[a])] = 1;
            // The organs rest on their posterior surfaces (the phantom's base, the back).
            if (f.normal.y() > 0.5) fixed[static_cast<std::size_t>(f.nodes[a])] = 1;
        }
    for (std::size_t n = 0; n < fixed.size(); ++n) {
        if (fixed[n]) gt.fixed_nodes.push_back(static_cast<std::int32_t>(n));
        if (boundary[n]) gt.boundary_nodes.push_back(static_cast<std::int32_t>(n));
    }
    // Every piece needs support, else the static problem has rigid modes.
    std::vector<std::int32_t> parent(gt.mesh.node_count());
    std::iota(parent.begin(), parent.end(), 0);
    std::function<std::int32_t(std::int32_t)> root = [&](std::int32_t q) { return parent[q] == q ? q : parent[q] = root(parent[q]); };
    for (std::size_t c = 0; c < gt.mesh.cell_count(); ++c) {
        const auto cell = gt.mesh.cell(c);
        for (int a = 1; a < gt.mesh.cell_size(); ++a) parent[root(cell[a])] = root(cell[0]);
    }
    std::set<std::int32_t> supported;
    for (const auto n : gt.fixed_nodes) supported.insert(root(n));
    for (std::size_t n = 0; n < gt.mesh.node_count(); ++n)
        if (!supported.count(root(static_cast<std::int32_t>(n))))
            fail("ground truth: a piece of the organs (node {} at {:.1f}, {:.1f}, {:.1f} mm) has no posterior surface to rest on",
                 n, gt.mesh.nodes[n].x(), gt.mesh.nodes[n].y(), gt.mesh.nodes[n].z());
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

std::vector<CompressionSpec> default_compressions(const Prepared& p, const PhantomSpec& spec, const Vec3& lo, const Vec3& hi,
                                                  double image_length)
{
    // Five positions over the liver, as fractions of its x (right→left) and z (inferior→superior) extent.
    const std::pair<double, double> pattern[] = {{0.45, 0.5}, {0.25, 0.45}, {0.62, 0.55}, {0.4, 0.25}, {0.55, 0.75}};
    std::vector<CompressionSpec> out;
    const Vec3 start_y(0, lo.y() - 0.5 * image_length, 0);
    for (int c = 0; c < 5; ++c) {
        CompressionSpec s;
        s.name = std::string(1, static_cast<char>('A' + c));
        s.tool = spec.tool;
        s.depth_mm = spec.depths_mm[static_cast<std::size_t>(c) % spec.depths_mm.size()];
        const double x0 = lo.x() + pattern[c].first * (hi.x() - lo.x()), z0 = lo.z() + pattern[c].second * (hi.z() - lo.z());
        // Nearest column (in 2 mm rings) through the liver.
        bool found = false;
        for (double r = 0; r <= 60 && !found; r += 2)
            for (int a = 0; a < std::max(1, static_cast<int>(std::ceil(2 * M_PI * r / 2))) && !found; ++a) {
                const double angle = r == 0 ? 0 : 2 * M_PI * a / std::ceil(2 * M_PI * r / 2);
                const double x = x0 + r * std::cos(angle), z = z0 + r * std::sin(angle);
                // A column through enough liver that the depth stays well inside it.
                const double thickness = length_inside(p.labels, Vec3(x, start_y.y(), z), Vec3::UnitY(), 2 * image_length,
                                                       [&](std::int32_t l) { return p.roles.is_liver_tissue(l); });
                if (thickness >= std::max(30.0, 2.5 * s.depth_mm)) {
                    s.x_mm = x;
                    s.z_mm = z;
                    found = true;
                }
            }
        if (!found) fail("compression {}: no column through ≥ {:.0f} mm of liver within 60 mm of x = {:.1f}, z = {:.1f} mm", s.name, std::max(30.0, 2.5 * s.depth_mm), x0, z0);
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
    long iterations = 0, pilot_iterations = 0;
    double seconds = 0.0;
    double max_displacement_mm = 0.0;
    double max_penetration_mm = 0.0;
    std::optional<Indenter> tool;
    CompressionSpec compression;
    double pressure_pa = 0.0;
};

double max_norm(const std::vector<double>& u)
{
    double m = 0.0;
    for (std::size_t n = 0; n + 2 < u.size(); n += 3) m = std::max(m, std::sqrt(u[n] * u[n] + u[n + 1] * u[n + 1] + u[n + 2] * u[n + 2]));
    return m;
}

template <typename Real>
GroundTruthSolution solve_with(const TledModel& model, const Loads& loads, const EquilibriumOptions& options, int load_steps,
                               const std::vector<std::int32_t>& surface_nodes, const std::string& what, const std::vector<double>* initial)
{
    TledSolver<Real> solver(model);
    solver.set_loads(loads);
    if (initial) solver.set_displacement(*initial);
    GroundTruthSolution s;
    const auto t0 = std::chrono::steady_clock::now();
    for (int step = 1; step <= load_steps; ++step) {
        EquilibriumOptions o = options;
        if (step < load_steps) o.displacement_tolerance_mm *= 10.0;
        SolveSummary summary;
        try {
            summary = solver.solve_equilibrium(o, static_cast<double>(step) / load_steps);
        } catch (const Error& e) {
            fail("ground truth for {}: {} (load step {} of {}; try a smaller depth or a larger tool)", what, e.what(), step, load_steps);
        }
        s.iterations += summary.iterations;
        if (!summary.converged())
            fail("ground truth for {}: no equilibrium after {} iterations (load step {} of {}): {}", what, summary.iterations, step,
                 load_steps, summary.message);
    }
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.displacement_mm = solver.displacement_mm();
    s.max_displacement_mm = max_norm(s.displacement_mm);
    const auto& rest = model.rest_positions();
    const auto& u = s.displacement_mm;
    for (const auto& tool : solver.loads().indenters)
        for (const auto n : surface_nodes) {
            const auto q = 3 * static_cast<std::size_t>(n);
            const Vec3 x(rest[q] + u[q], rest[q + 1] + u[q + 1], rest[q + 2] + u[q + 2]);
            Vec3 surface, normal;
            if (tool.push_out(x, 1.0, surface, normal)) s.max_node_penetration_mm = std::max(s.max_node_penetration_mm, (surface - x).norm());
        }
    return s;
}

SolvedState solved_from(const GroundTruthSolution& solution)
{
    SolvedState s;
    s.u = solution.displacement_mm;
    s.iterations = solution.iterations;
    s.seconds = solution.seconds;
    s.max_displacement_mm = solution.max_displacement_mm;
    s.max_penetration_mm = solution.max_node_penetration_mm;
    return s;
}

// Loads of one state on a model: the posterior support plus `extra` (tools or pressure).
using LoadMaker = std::function<Loads(const GroundTruth&)>;

Loads supported(const GroundTruth& m)
{
    Loads loads;
    loads.constraints.push_back({"posterior_support", m.fixed_nodes, {true, true, true}, Vec3::Zero()});
    return loads;
}

// Nested solve: the pilot model (half the resolution) goes to equilibrium from rest with the loads
// ramped; its displacement, interpolated, starts the fine model, whose relaxation then only has to
// resolve what the pilot could not (≈ 2× fewer fine iterations than a ramp on the fine model).
SolvedState solve_state(const GroundTruth& gt, const PhantomSpec& spec, const LoadMaker& pilot_loads, long pilot_ramp,
                        const LoadMaker& fine_loads, long fine_ramp, long direct_ramp, const std::string& what)
{
    if (!gt.pilot) { // a small model: `pilot_loads` on the fine model, from rest
        EquilibriumOptions options = spec.equilibrium;
        options.ramp_iterations = direct_ramp;
        return solved_from(solve_ground_truth(*gt.model, pilot_loads(gt), options, 1, spec.single_precision, gt.boundary_nodes, what));
    }
    EquilibriumOptions pilot_options = spec.equilibrium;
    pilot_options.displacement_tolerance_mm *= 4.0;
    pilot_options.ramp_iterations = pilot_ramp;
    const GroundTruthSolution pilot = solve_ground_truth(*gt.pilot->model, pilot_loads(*gt.pilot), pilot_options, 1,
                                                         spec.single_precision, gt.pilot->boundary_nodes, what + " (pilot)");
    // The pilot's one-point hexahedra carry hourglass patterns under a tool; interpolated as they are,
    // they can fold fine elements. Cell means then node means remove them (the pattern averages to
    // zero over a cell) and keep the smooth part, which is what the fine relaxation needs.
    logger()->debug("{}: pilot {} iterations, {:.1f} s", what, pilot.iterations, pilot.seconds);
    std::vector<double> smooth(pilot.displacement_mm.size(), 0.0);
    {
        const VolumeMesh& pm = gt.pilot->mesh;
        std::vector<double> cell_mean(3 * pm.cell_count(), 0.0), count(pm.node_count(), 0.0);
        for (std::size_t c = 0; c < pm.cell_count(); ++c)
            for (const auto n : pm.cell(c))
                for (int k = 0; k < 3; ++k) cell_mean[3 * c + k] += pilot.displacement_mm[3 * static_cast<std::size_t>(n) + k] / pm.cell_size();
        for (std::size_t c = 0; c < pm.cell_count(); ++c)
            for (const auto n : pm.cell(c)) {
                for (int k = 0; k < 3; ++k) smooth[3 * static_cast<std::size_t>(n) + k] += cell_mean[3 * c + k];
                count[static_cast<std::size_t>(n)] += 1.0;
            }
        for (std::size_t n = 0; n < pm.node_count(); ++n)
            for (int k = 0; k < 3; ++k) smooth[3 * n + k] /= count[n];
    }
    std::vector<double> start(3 * gt.mesh.node_count());
    for (std::size_t n = 0; n < gt.mesh.node_count(); ++n) {
        // Fine nodes outside the pilot mesh take the displacement of its nearest point (no extrapolation:
        // extrapolating a strongly deformed cell can fold the fine elements there).
        NodeEmbedding where = gt.nodes_in_pilot[n];
        where.natural = where.natural.cwiseMax(-1.0).cwiseMin(1.0);
        const auto u = interpolate_nodal(gt.pilot->mesh, where, smooth, 3);
        for (int k = 0; k < 3; ++k) start[3 * n + k] = u[static_cast<std::size_t>(k)];
    }
    const Loads loads = fine_loads(gt);
    for (const auto& c : loads.constraints)
        for (const auto n : c.nodes)
            for (int k = 0; k < 3; ++k)
                if (c.dofs[k]) start[3 * static_cast<std::size_t>(n) + k] = 0.0; // support: exactly fixed
    EquilibriumOptions fine_options = spec.equilibrium;
    fine_options.ramp_iterations = fine_ramp;
    GroundTruthSolution solution;
    try {
        solution = solve_ground_truth(*gt.model, loads, fine_options, 1, spec.single_precision, gt.boundary_nodes, what, &start);
    } catch (const Error& e) {
        // Where the pilot's coarser cells cannot follow a thin feature, the interpolated start can
        // fold a fine element; the fine model then relaxes from rest (slower, same criterion).
        logger()->warn("{}: the pilot's shape does not fit the fine model ({}); relaxing the fine model from rest", what, e.what());
        EquilibriumOptions options = spec.equilibrium;
        options.ramp_iterations = direct_ramp;
        solution = solve_ground_truth(*gt.model, pilot_loads(gt), options, 1, spec.single_precision, gt.boundary_nodes, what);
    }
    SolvedState s = solved_from(solution);
    s.pilot_iterations = pilot.iterations;
    s.seconds += pilot.seconds;
    return s;
}

SolvedState solve_compression(const GroundTruth& gt, const PhantomSpec& spec, const Prepared& p, const CompressionSpec& c)
{
    const Vec3 d = c.direction.normalized();
    const auto& g = p.labels.geometry;
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (int corner = 0; corner < 8; ++corner) {
        Vec3 index;
        for (int a = 0; a < 3; ++a) index[a] = ((corner >> a) & 1) ? double(g.size[a]) - 0.5 : -0.5;
        lo = lo.cwiseMin(g.index_to_physical(index));
        hi = hi.cwiseMax(g.index_to_physical(index));
    }
    const double length = (hi - lo).norm();
    // The line enters through the image's anterior (start of the pressing direction) side.
    const Vec3 centre_line(c.x_mm, 0.5 * (lo.y() + hi.y()), c.z_mm);
    const Vec3 start = centre_line - length * d;
    if (!line_hits(p.labels, start, d, 2 * length, [](std::int32_t l) { return l != 0; }))
        fail("compression {}: the tool line x = {:.1f} mm, z = {:.1f} mm misses the phantom's body (outside the body)", c.name, c.x_mm, c.z_mm);
    {
        // The tissue the tool presses on: organ voxels along its line. A depth near that thickness
        // would drive the tool through the organ.
        const double thickness = length_inside(p.labels, start, d, 2 * length, [&](std::int32_t l) { return gt.tissues.find(l) != nullptr; });
        if (c.depth_mm > 0.6 * thickness)
            fail("compression {}: depth {:.1f} mm exceeds 60 % of the organs' thickness along the tool's line ({:.1f} mm at x = {:.1f}, "
                 "z = {:.1f} mm)", c.name, c.depth_mm, thickness, c.x_mm, c.z_mm);
    }
    const GroundTruth& first = gt.pilot ? *gt.pilot : gt; // the model the tool meets first
    // A sphere slips through a cell face whose half-diagonal exceeds its radius.
    double across_squared = 0.0;
    for (int k = 0; k < 3; ++k)
        if (std::abs(d[k]) < 0.9) across_squared += first.cell_size[k] * first.cell_size[k];
    const double across = std::sqrt(across_squared);
    const double width = c.tool.shape == IndenterShape::box ? 2.0 * c.tool.half_extents_mm.minCoeff() : 2.0 * c.tool.radius_mm;
    if (width < across)
        fail("compression {}: the tool ({:.1f} mm across) is narrower than the ground-truth cells across the pressing direction "
             "({:.1f} mm); node-to-surface contact would let it slip between nodes — use a larger --tool-radius or a finer "
             "--ground-truth-grid", c.name, width, across);
    const double reach = c.tool.shape == IndenterShape::box ? c.tool.half_extents_mm.norm() : c.tool.radius_mm;
    Indenter probe = make_indenter(c, start, start + 3 * length * d);
    probe.validate();
    // First contact: the smallest travel at which a boundary node is inside the tool.
    std::vector<Vec3> candidates;
    for (const auto n : gt.boundary_nodes) {
        const Vec3& x = gt.mesh.nodes[static_cast<std::size_t>(n)];
        const Vec3 r = x - start;
        const bool near_line = (r - r.dot(d) * d).norm() <= reach + 1.0 || c.tool.shape == IndenterShape::cylinder;
        if (near_line) candidates.push_back(x);
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
    if (t_hit < 0) fail("compression {}: the tool along x = {:.1f} mm, z = {:.1f} mm never touches the organs", c.name, c.x_mm, c.z_mm);
    double a = std::max(0.0, t_hit - 0.5), b = t_hit;
    for (int it = 0; it < 30; ++it) (touches(0.5 * (a + b)) ? b : a) = 0.5 * (a + b);
    const Vec3 contact = start + a * d, end = contact + c.depth_mm * d;
    // The tool moves during the first iterations. Information travels about one element per
    // relaxation iteration, so a tool faster than ~1 % of the smallest cell per iteration crushes the
    // elements under it; the smooth ramp peaks at 1.875× its mean speed. The pilot's tool starts two
    // of its cells back (its coarser surface may stand proud of the fine one); the fine model starts
    // from the pilot's shape with its tool two pilot cells back, then pressed home.
    const double pilot_h = first.cell_size.minCoeff(), back = 2.0 * first.cell_size.maxCoeff();
    auto ramp = [&](double travel, double h) {
        return std::max<long>(spec.equilibrium.ramp_iterations, std::lround(std::ceil(1.875 * travel / (spec.tool_speed_per_cell * h))));
    };
    const LoadMaker pilot_loads = [&](const GroundTruth& m) {
        Loads loads = supported(m);
        loads.indenters.push_back(make_indenter(c, contact - back * d, end));
        return loads;
    };
    const LoadMaker fine_loads = [&](const GroundTruth& m) {
        Loads loads = supported(m);
        loads.indenters.push_back(make_indenter(c, end - back * d, end));
        return loads;
    };
    SolvedState s = solve_state(gt, spec, pilot_loads, ramp(c.depth_mm + back, pilot_h), fine_loads, ramp(back, gt.cell_size.minCoeff()),
                                ramp(c.depth_mm + back, gt.cell_size.minCoeff()), "compression " + c.name);
    s.tool = make_indenter(c, contact, end);
    // Node-to-surface contact holds nodes, not faces: a tool too small for the cells can slip between
    // surface nodes into the tissue. Then deformed cell centres end up inside the tool.
    for (std::size_t e = 0; e < gt.mesh.cell_count(); ++e) {
        Vec3 centre = Vec3::Zero();
        for (const auto n : gt.mesh.cell(e)) {
            const auto q = 3 * static_cast<std::size_t>(n);
            centre += (gt.mesh.nodes[static_cast<std::size_t>(n)] + Vec3(s.u[q], s.u[q + 1], s.u[q + 2])) / gt.mesh.cell_size();
        }
        Vec3 surface, normal;
        // Cells wrapped around the tool have their centres inside it by the chord sag; a slipped tool
        // swallows whole cells.
        if (s.tool->push_out(centre, 1.0, surface, normal) && (surface - centre).norm() > 0.5 * gt.cell_size.minCoeff())
            fail("compression {}: the tool slipped past the surface nodes into the tissue (element {} ends inside it; use a larger "
                 "tool or a finer ground-truth grid)", c.name, e);
    }
    s.compression = c;
    return s;
}

SolvedState solve_insufflation(const GroundTruth& gt, const PhantomSpec& spec, double pressure_pa)
{
    // Pressure on the anterior-facing surface (dead load along the rest normal): N = Pa · 1e-6 · mm².
    const LoadMaker pressure_loads = [&](const GroundTruth& m) {
        Loads loads = supported(m);
        loads.external_forces_n.assign(3 * m.mesh.node_count(), 0.0);
        for (const auto& f : m.faces) {
            if (f.normal.y() > -0.2) continue;
            const Vec3 force = -pressure_pa * 1e-6 * f.area * f.normal;
            for (int a = 0; a < f.count; ++a)
                for (int k = 0; k < 3; ++k) loads.external_forces_n[3 * static_cast<std::size_t>(f.nodes[a]) + k] += force[k] / f.count;
        }
        return loads;
    };
    // The fine model starts from the pilot's shape under the full pressure at once (ramp of 1).
    SolvedState s = solve_state(gt, spec, pressure_loads, spec.equilibrium.ramp_iterations, pressure_loads, 1,
                                spec.equilibrium.ramp_iterations, "insufflation");
    s.pressure_pa = pressure_pa;
    return s;
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

GroundTruthSolution solve_ground_truth(const TledModel& model, const Loads& loads, const EquilibriumOptions& options, int load_steps,
                                       bool single_precision, const std::vector<std::int32_t>& surface_nodes, const std::string& what,
                                       const std::vector<double>* initial)
{
    if (load_steps < 1) fail("ground truth for {}: {} load steps", what, load_steps);
    if (initial && initial->size() != 3 * model.node_count())
        fail("ground truth for {}: initial displacement has {} values for {} nodes", what, initial->size(), model.node_count());
    return single_precision ? solve_with<float>(model, loads, options, load_steps, surface_nodes, what, initial)
                            : solve_with<double>(model, loads, options, load_steps, surface_nodes, what, initial);
}

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
        if (!out) fail("cannot write '{}'", path.string());
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
    const ScalarImage intensity = synthesize_mr_intensity(p.labels, p.roles, mix_seed(spec.seed, "intensity"));
    Vec3 liver_lo, liver_hi;
    const Vec3 liver_centre = liver_centroid(p, liver_lo, liver_hi);
    timings["anatomy_s"] = seconds_since(clock0);

    report(0.03, "ground-truth mesh");
    auto t = std::chrono::steady_clock::now();
    GroundTruth gt = build_ground_truth(p, spec);
    const auto deforming = [&](std::int32_t l) { return gt.tissues.find(l) != nullptr; };
    const auto is_liver = [&](std::int32_t l) { return p.roles.is_liver_tissue(l); };
    timings["ground_truth_model_s"] = seconds_since(t);

    report(0.05, "landmarks");
    t = std::chrono::steady_clock::now();
    const LandmarkSet rest_landmarks = pick_landmarks(p.labels, p.roles);
    std::vector<Vec3> landmark_points;
    for (const auto& l : rest_landmarks) landmark_points.push_back(l.position);
    const auto landmark_cells = embed_in_grid_mesh(gt.mesh, landmark_points);
    for (std::size_t l = 0; l < rest_landmarks.size(); ++l)
        if (!landmark_cells[l].inside && landmark_cells[l].distance_mm > 1.5 * gt.cell_size.maxCoeff())
            fail("landmark {} lies {:.2f} mm outside the ground-truth mesh", rest_landmarks[l].name, landmark_cells[l].distance_mm);
    const auto notch_x = find_margin_notch_x(p.labels, p.roles);
    const BoundarySurface liver_surface = liver_boundary(gt.mesh, is_liver, notch_x);
    timings["landmarks_s"] = seconds_since(t);

    // The experiment's states.
    std::vector<CompressionSpec> compressions = spec.compressions;
    const auto& g = p.labels.geometry;
    const double image_length = g.spacing.cwiseProduct(Vec3(double(g.size[0]), double(g.size[1]), double(g.size[2]))).norm();
    if (compressions.empty()) compressions = default_compressions(p, spec, liver_lo, liver_hi, image_length);
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
    json tissues = json::array();
    for (const auto& tissue : gt.tissues.tissues)
        tissues.push_back({{"label", tissue.label}, {"name", tissue.name}, {"young_modulus_pa", tissue.young_modulus_pa},
                           {"poisson_ratio", tissue.poisson_ratio}, {"density_kg_m3", tissue.density_kg_m3}});
    manifest["tissues"] = tissues;
    write_tissue_table(root / "tissues.yaml", gt.tissues);
    manifest["tissues_file"] = "tissues.yaml";
    const auto& grid = *gt.mesh.grid;
    manifest["ground_truth"] = {
        {"model", "TLED, Neo-Hookean, uniform-strain hexahedra with hourglass control; tissues share nodes (no coupling)"},
        {"grid_dims", json::array({grid.dims[0], grid.dims[1], grid.dims[2]})},
        {"cell_size_mm", to_json(grid.cell_size)},
        {"liver_grid_requested", json::array({spec.ground_truth_grid[0], spec.ground_truth_grid[1], spec.ground_truth_grid[2]})},
        {"nodes", gt.mesh.node_count()},
        {"elements", gt.mesh.cell_count()},
        {"fixed_nodes", gt.fixed_nodes.size()},
        {"pilot_grid_dims", gt.pilot ? json::array({gt.pilot->mesh.grid->dims[0], gt.pilot->mesh.grid->dims[1], gt.pilot->mesh.grid->dims[2]}) : json()},
        {"support", "organ surface faces facing posterior (outward normal y > 0.5) are fixed"},
        {"precision", spec.single_precision ? "float" : "double"},
        {"equilibrium", {{"displacement_tolerance_mm", spec.equilibrium.displacement_tolerance_mm},
                         {"residual_tolerance", spec.equilibrium.residual_tolerance},
                         {"criterion", "estimated distance to equilibrium and largest free residual / largest internal force"}}}};
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
    const std::uint16_t fill_label = p.roles.body.empty() ? 0 : static_cast<std::uint16_t>(*p.roles.body.begin());
    const double extension_mm = 1.5 * gt.cell_size.maxCoeff();

    json states = json::array();
    const int state_count = 1 + static_cast<int>(compressions.size()) + (pressure > 0 ? 1 : 0);
    int state_index = 0;
    auto write_state = [&](const std::string& name, const std::string& kind, const SolvedState* solved) {
        const double f0 = 0.08 + 0.92 * state_index / state_count;
        const std::string dir = name == "rest" ? "rest" : "states/" + name;
        fs::create_directories(root / dir);
        json s;
        s["name"] = name;
        s["kind"] = kind;
        json files;
        const std::vector<double> zero(3 * gt.mesh.node_count(), 0.0);
        const std::vector<double>& u = solved ? solved->u : zero;
        LabelVolume labels = p.labels;
        ScalarImage image = intensity;
        if (solved) {
            report(f0 + 0.6 / state_count, name + ": images");
            const InverseMap map = rasterize_inverse_map(gt.mesh, u, g, extension_mm);
            labels = warp_labels(p.labels, map, deforming, fill_label);
            image = warp_intensity(intensity, p.labels, labels, map, deforming, static_cast<float>(fill_intensity));
            if (solved->tool) paint_tool(labels, image, *solved->tool, solved->compression.direction.normalized(), deforming);
            files["inverse_displacement"] = write_file(root, dir + "/inverse_displacement.nii.gz",
                                                       [&](const fs::path& f) { write_displacement_field(f, map.field); });
            const SampledField forward = sample_displacement_field(gt.mesh, u, g);
            files["displacement"] = write_file(root, dir + "/displacement.nii.gz",
                                               [&](const fs::path& f) { write_displacement_field(f, forward.field); });
        }
        files["labels"] = write_file(root, dir + "/labels.nii.gz", [&](const fs::path& f) { write_label_volume(f, labels); });
        files["intensity"] = write_file(root, dir + "/intensity.nii.gz", [&](const fs::path& f) { write_scalar_image(f, image); });
        MeshData data;
        data.point_data.push_back({"displacement", 3, u});
        files["mesh"] = write_file(root, dir + "/mesh.vtu", [&](const fs::path& f) { write_vtu(f, gt.mesh, data); });
        const LandmarkSet landmarks = solved ? move_landmarks(rest_landmarks, landmark_cells, gt.mesh, u) : rest_landmarks;
        files["landmarks"] = write_file(root, dir + "/landmarks.csv", [&](const fs::path& f) { write_landmarks(f, landmarks); });
        files["landmarks_noisy"] = write_file(root, dir + "/landmarks_noisy.csv", [&](const fs::path& f) {
            write_landmarks(f, with_noise(landmarks, spec.landmark_noise_mm, mix_seed(spec.seed, "landmarks/" + name)));
        });
        files["liver_surface"] = write_file(root, dir + "/liver_surface.ply", [&](const fs::path& f) { write_boundary_ply(f, gt.mesh, u, liver_surface); });
        json surfaces = json::object();
        if (solved) {
            for (const int percent : spec.surface_percentages) {
                const auto cloud = visible_surface_patch(gt.mesh, u, liver_surface, percent / 100.0, Vec3::UnitY(), spec.surface_noise_mm,
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
        if (solved) title += fmt::format(", MAX DISPL. {:.1f} MM", solved->max_displacement_mm);
        figure.title = title;
        figure.pixels_per_mm = std::clamp(600.0 / (g.spacing.x() * g.size[0]), 0.5, 4.0);
        const Canvas canvas = render_orthogonal_slices(image, labels, p.roles, landmarks, {}, figure);
        files["picture"] = write_file(root, dir + "/slices.png", [&](const fs::path& f) { write_png(f, canvas.image()); });
        s["files"] = files;
        if (solved) {
            s["max_displacement_mm"] = solved->max_displacement_mm;
            s["iterations"] = solved->iterations;
            s["pilot_iterations"] = solved->pilot_iterations;
            s["max_node_penetration_mm"] = solved->max_penetration_mm;
            if (solved->tool) {
                const auto& c = solved->compression;
                s["tool"] = {{"shape", shape_name(solved->tool->shape)}, {"radius_mm", solved->tool->radius_mm},
                             {"axis", to_json(solved->tool->axis)}, {"half_extents_mm", to_json(solved->tool->half_extents_mm)},
                             {"entry_x_mm", c.x_mm}, {"entry_z_mm", c.z_mm}, {"direction", to_json(c.direction.normalized())},
                             {"contact_position_mm", to_json(solved->tool->path.front())},
                             {"final_position_mm", to_json(solved->tool->path.back())}};
                s["depth_mm"] = c.depth_mm;
            } else {
                s["pressure_pa"] = solved->pressure_pa;
                s["pressure_faces"] = "organ surface faces facing anterior (outward normal y < -0.2), dead load";
            }
        }
        states.push_back(s);
        ++state_index;
    };

    write_state("rest", "rest", nullptr);
    for (const auto& c : compressions) {
        report(0.08 + 0.92 * state_index / state_count, "compression " + c.name + ": solving");
        t = std::chrono::steady_clock::now();
        const SolvedState solved = solve_compression(gt, spec, p, c);
        timings["solve_" + c.name + "_s"] = solved.seconds;
        logger()->info("compression {}: depth {} mm, {} iterations, {:.1f} s, max displacement {:.2f} mm", c.name, c.depth_mm,
                       solved.iterations, solved.seconds, solved.max_displacement_mm);
        write_state(c.name, "compression", &solved);
        timings["state_" + c.name + "_s"] = seconds_since(t);
    }
    if (pressure > 0) {
        report(0.08 + 0.92 * state_index / state_count, "insufflation: solving");
        t = std::chrono::steady_clock::now();
        const SolvedState solved = solve_insufflation(gt, spec, pressure);
        timings["solve_insufflation_s"] = solved.seconds;
        logger()->info("insufflation: {:.0f} Pa, {} iterations, {:.1f} s, max displacement {:.2f} mm", pressure, solved.iterations,
                       solved.seconds, solved.max_displacement_mm);
        write_state("insufflation", "insufflation", &solved);
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

PhantomDataset read_phantom_dataset(const fs::path& directory)
{
    const fs::path path = directory / "manifest.json";
    std::ifstream in(path);
    if (!in) fail("dataset '{}': no manifest.json (not a physreg phantom dataset?)", directory.string());
    json m;
    try {
        in >> m;
    } catch (const json::exception& e) {
        fail("dataset manifest '{}': not valid JSON: {}", path.string(), e.what());
    }
    PhantomDataset d;
    d.directory = directory;
    try {
        if (m.at("format").get<std::string>() != "physreg-phantom-dataset") fail("dataset manifest '{}': format is not physreg-phantom-dataset", path.string());
        const int version = m.at("format_version").get<int>();
        if (version != format_version) fail("dataset manifest '{}': format version {} (this physreg reads {})", path.string(), version, format_version);
        d.generator_version = m.at("generator").at("version").get<std::string>();
        d.seed = m.at("generator").at("seed").get<std::uint64_t>();
        d.preset = m.at("generator").at("preset").get<std::string>();
        const auto requested = m.at("ground_truth").at("liver_grid_requested").get<std::vector<std::int64_t>>();
        if (requested.size() == 3) d.ground_truth_grid = {requested[0], requested[1], requested[2]};
        const auto& r = m.at("label_roles");
        d.roles.body = r.at("body").get<std::set<std::int32_t>>();
        d.roles.liver = r.at("liver").get<std::set<std::int32_t>>();
        d.roles.lesion = r.at("lesion").get<std::set<std::int32_t>>();
        d.roles.vessel = r.at("vessel").get<std::set<std::int32_t>>();
        d.roles.bone = r.at("bone").get<std::set<std::int32_t>>();
        d.roles.kidney = r.at("kidney").get<std::set<std::int32_t>>();
        d.tissues_file = m.at("tissues_file").get<std::string>();
        for (const auto& s : m.at("states")) {
            DatasetState state;
            state.name = s.at("name").get<std::string>();
            state.kind = s.at("kind").get<std::string>();
            state.files = s.at("files").get<std::map<std::string, std::string>>();
            for (const auto& [percent, entry] : s.at("partial_surfaces").items())
                state.surfaces[std::stoi(percent)] = {entry.at("ply").get<std::string>(), entry.at("csv").get<std::string>()};
            state.max_displacement_mm = s.value("max_displacement_mm", 0.0);
            state.depth_mm = s.value("depth_mm", 0.0);
            if (s.contains("tool")) {
                const auto& t = s.at("tool");
                auto vec = [](const json& v) { return Vec3(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>()); };
                Indenter tool;
                tool.name = "tool_" + state.name;
                tool.shape = parse_indenter_shape(t.at("shape").get<std::string>());
                tool.radius_mm = t.at("radius_mm").get<double>();
                tool.axis = vec(t.at("axis"));
                tool.half_extents_mm = vec(t.at("half_extents_mm"));
                tool.path = {vec(t.at("contact_position_mm")), vec(t.at("final_position_mm"))};
                try {
                    tool.validate();
                } catch (const Error& e) {
                    fail("dataset manifest '{}': state {}: tool: {}", path.string(), state.name, e.what());
                }
                state.tool = tool;
            }
            d.states.push_back(state);
        }
    } catch (const json::exception& e) {
        fail("dataset manifest '{}': missing or malformed entry: {}", path.string(), e.what());
    }
    if (d.states.empty() || d.states.front().name != "rest") fail("dataset manifest '{}': the first state must be 'rest'", path.string());
    auto check = [&](const std::string& relative) {
        if (!fs::exists(directory / relative)) fail("dataset '{}': listed file '{}' does not exist", directory.string(), relative);
    };
    check(d.tissues_file);
    for (const auto& s : d.states) {
        for (const auto& [role, file] : s.files) check(file);
        for (const auto& [percent, files] : s.surfaces) check(files.first), check(files.second);
    }
    return d;
}

} // namespace physreg
