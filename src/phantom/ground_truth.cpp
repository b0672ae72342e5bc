// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/ground_truth.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/progress_note.hpp"
#include "physreg/mechanics/simulation/calculix.hpp"
#include "physreg/phantom/dataset.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <sstream>

namespace physreg {

using json = nlohmann::json;

void GroundTruthMeshing::validate() const
{
    for (const auto& [name, v] : {std::pair<const char*, double>{"organ cell size", organ_cell_mm}, {"kidney cell size", kidney_cell_mm},
                                  {"body cell size", body_cell_mm}, {"facet size", facet_mm}, {"facet distance", facet_distance_mm}})
        if (!(std::isfinite(v) && v > 0.0 && v <= 100.0)) fail("ground-truth mesh: {} = {} mm must lie in (0, 100]", name, v);
}

TissueTable draw_ground_truth_tissues(MaterialSet set, const LabelRoles& roles, const std::set<std::int32_t>& present, std::uint64_t seed,
                                      json& ranges)
{
    // The literature values the registration models start from (paper 000 / paper 001).
    double parenchyma = 2e5, vessel = 1e6, lesion = 5e6;
    if (set != MaterialSet::paper000) {
        parenchyma = set == MaterialSet::healthy ? 3.5e3 : 3.0e4;
        vessel = 6.2e5;
        lesion = 10 * parenchyma;
    }
    SeededRandom random(seed ^ 0xA5A5F00DCAFEBEEFull);
    // Organ moduli: the literature value times a log-uniform factor in [1/2, 2] (a factor 4 of
    // uncertainty, as between published liver moduli); gel: uniform in 10–30 kPa.
    const auto log_uniform = [&](double centre) { return centre * std::pow(2.0, 2.0 * random.uniform() - 1.0); };
    const double factor_range[2] = {0.5, 2.0};
    const double gel_range[2] = {1.0e4, 3.0e4};
    const double c01_range[2] = {0.1, 0.5};
    TissueTable table;
    auto add = [&](const std::set<std::int32_t>& labels, const std::string& name, double e, double nu) {
        int n = 0;
        for (const auto label : labels) {
            if (!present.count(label)) continue;
            Tissue t{label, n++ == 0 ? name : fmt::format("{}_{}", name, label), e, nu, 1000.0};
            t.mooney_rivlin_c01_fraction = c01_range[0] + (c01_range[1] - c01_range[0]) * random.uniform();
            table.tissues.push_back(t);
        }
    };
    const double nu_organ = 0.495, nu_gel = 0.497;
    const double parenchyma_e = log_uniform(parenchyma);
    add(roles.liver, "parenchyma", parenchyma_e, nu_organ);
    add(roles.lesion, "lesion", log_uniform(lesion), nu_organ);
    add(roles.vessel, "vessel", log_uniform(vessel), nu_organ);
    add(roles.kidney, "kidney", 2.5 * log_uniform(parenchyma), nu_organ);
    add(roles.body, "body", gel_range[0] + (gel_range[1] - gel_range[0]) * random.uniform(), nu_gel);
    for (const auto label : present)
        if (label != 0 && !table.find(label)) table.ignored_labels.insert(label);
    table.validate("ground-truth materials");
    ranges = {{"organs", fmt::format("literature value ({} set: parenchyma {} Pa, lesion {} Pa, vessel {} Pa, kidney 2.5x parenchyma) "
                                     "times a log-uniform factor in [{}, {}]", to_string(set), parenchyma, lesion, vessel,
                                     factor_range[0], factor_range[1])},
              {"body_gel_pa", {gel_range[0], gel_range[1]}},
              {"body_gel_source", "uniform over the 10-30 kPa the CIRS gels are quoted at (issue 17); the 057A data sheet gives no modulus"},
              {"mooney_rivlin_c01_fraction", {c01_range[0], c01_range[1]}},
              {"poisson_ratio", {{"body", 0.497}, {"organs", 0.495}}}};
    return table;
}

namespace {

std::vector<std::int32_t> supported_face_nodes(const VolumeMesh& mesh, const std::vector<BoundaryFace>& faces, const OrganSupport& support)
{
    std::vector<char> mark(mesh.node_count(), 0);
    const Vec3 d = support.direction.normalized();
    for (const auto& f : faces)
        if (f.normal.dot(d) > 0.5)
            for (int a = 0; a < f.count; ++a) mark[static_cast<std::size_t>(f.nodes[a])] = 1;
    std::vector<std::int32_t> out;
    for (std::size_t n = 0; n < mark.size(); ++n)
        if (mark[n]) out.push_back(static_cast<std::int32_t>(n));
    if (out.empty()) fail("ground truth: no organ surface face faces {} (outward normal · ({:.2f}, {:.2f}, {:.2f}) > 0.5) to hold the organs by", support.name, d.x(), d.y(), d.z());
    return out;
}

std::string organ_support_text(const OrganSupport& s)
{
    const Vec3 d = s.direction.normalized();
    return fmt::format("surface faces facing {} (outward normal · ({:.2f}, {:.2f}, {:.2f}) > 0.5) fixed", s.name, d.x(), d.y(), d.z());
}

// Cells kept by `keep`, nodes renumbered; `old_of_new` maps back.
VolumeMesh extract_cells(const VolumeMesh& mesh, const std::function<bool(std::int32_t)>& keep, std::vector<std::int32_t>& new_of_old)
{
    VolumeMesh out;
    out.cell_type = mesh.cell_type;
    new_of_old.assign(mesh.node_count(), -1);
    for (std::size_t c = 0; c < mesh.cell_count(); ++c) {
        if (!keep(mesh.cell_labels[c])) continue;
        for (const auto n : mesh.cell(c)) {
            auto& id = new_of_old[static_cast<std::size_t>(n)];
            if (id < 0) {
                id = static_cast<std::int32_t>(out.nodes.size());
                out.nodes.push_back(mesh.nodes[static_cast<std::size_t>(n)]);
            }
            out.cells.push_back(id);
        }
        out.cell_labels.push_back(mesh.cell_labels[c]);
    }
    return out;
}

// Every connected piece must touch a constraint, else the static problem has rigid modes.
void check_supported(const GroundTruthModel& m)
{
    std::vector<std::int32_t> parent(m.mesh.node_count());
    std::iota(parent.begin(), parent.end(), 0);
    std::function<std::int32_t(std::int32_t)> root = [&](std::int32_t q) { return parent[q] == q ? q : parent[q] = root(parent[q]); };
    for (std::size_t c = 0; c < m.mesh.cell_count(); ++c) {
        const auto cell = m.mesh.cell(c);
        for (int a = 1; a < m.mesh.cell_size(); ++a) parent[root(cell[a])] = root(cell[0]);
    }
    std::set<std::int32_t> supported;
    for (const auto& c : m.supports.constraints)
        for (const auto n : c.nodes) supported.insert(root(n));
    for (std::size_t n = 0; n < m.mesh.node_count(); ++n)
        if (!supported.count(root(static_cast<std::int32_t>(n))))
            fail("ground truth ({}): a piece of the mesh (node {} at {:.1f}, {:.1f}, {:.1f} mm) touches no support", m.name, n,
                 m.mesh.nodes[n].x(), m.mesh.nodes[n].y(), m.mesh.nodes[n].z());
}

void finish(GroundTruthModel& m, const TissueTable& tissues, double organ_cell_mm)
{
    m.mesh.validate("ground-truth mesh (" + m.name + ")");
    m.faces = boundary_faces(m.mesh);
    for (const auto l : m.mesh.cell_labels) m.labels.insert(l);
    m.quality = measure_tetrahedra(m.mesh);
    m.organ_cell_mm = organ_cell_mm;
    TledOptions options;
    options.law = MaterialLaw::mooney_rivlin;
    m.model = std::make_unique<TledModel>(m.mesh, tissues, options);
    check_supported(m);
}

} // namespace

OrganSupport parse_organ_support(const std::string& text, const std::string& what)
{
    static const std::map<std::string, Vec3> named = {{"posterior", Vec3::UnitY()},  {"anterior", -Vec3::UnitY()}, {"superior", Vec3::UnitZ()},
                                                      {"inferior", -Vec3::UnitZ()}, {"left", Vec3::UnitX()},      {"right", -Vec3::UnitX()}};
    if (const auto it = named.find(text); it != named.end()) return {text, it->second};
    std::vector<double> v;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        const auto x = parse_number(item);
        if (!x || !std::isfinite(*x)) fail("{}: '{}' is neither posterior, anterior, superior, inferior, left, right nor x,y,z", what, text);
        v.push_back(*x);
    }
    if (v.size() != 3) fail("{}: '{}' is neither posterior, anterior, superior, inferior, left, right nor x,y,z", what, text);
    const Vec3 d(v[0], v[1], v[2]);
    if (!(d.norm() > 0.0)) fail("{}: '{}' must be a non-zero direction", what, text);
    return {fmt::format("direction ({:g}, {:g}, {:g})", v[0], v[1], v[2]), d};
}

GroundTruthModel build_body_model(const LabelVolume& labels, const LabelRoles& roles, const TissueTable& tissues,
                                  const GroundTruthMeshing& meshing, unsigned seed, const OrganSupport& organ_support)
{
    meshing.validate();
    std::vector<char> seen(65536, 0); // labels present in the volume (a set per voxel would be slow)
    for (const auto l : labels.labels) seen[l] = 1;
    const auto present = [&](std::int32_t l) { return l >= 0 && l < 65536 && seen[static_cast<std::size_t>(l)]; };
    bool has_body = false;
    for (const auto& t : tissues.tissues) has_body |= roles.body.count(t.label) > 0;
    TetMeshingOptions o;
    o.default_cell_size_mm = meshing.body_cell_mm;
    o.facet_size_mm = meshing.facet_mm;
    o.facet_distance_mm = meshing.facet_distance_mm;
    o.seed = seed;
    for (const auto& t : tissues.tissues) {
        o.labels.insert(t.label);
        o.cell_size_mm[t.label] = roles.kidney.count(t.label) ? meshing.kidney_cell_mm
                                  : roles.body.count(t.label) ? meshing.body_cell_mm
                                                              : meshing.organ_cell_mm;
    }
    const bool has_bone = has_body && std::any_of(roles.bone.begin(), roles.bone.end(), present);
    if (has_bone)
        for (const auto l : roles.bone)
            if (present(l)) o.labels.insert(l), o.cell_size_mm[l] = meshing.body_cell_mm;
    const VolumeMesh full = mesh_labels_tetrahedral(labels, o, "ground-truth mesh");

    GroundTruthModel m;
    m.name = has_body ? "body" : "organs";
    std::vector<std::int32_t> new_of_old;
    m.mesh = extract_cells(full, [&](std::int32_t l) { return tissues.find(l) != nullptr; }, new_of_old);
    if (m.mesh.cell_count() == 0) fail("ground-truth mesh: no tetrahedron of a deforming tissue");
    if (!has_body) {
        m.faces = boundary_faces(m.mesh);
        m.supports.constraints.push_back({organ_support.name + "_support", supported_face_nodes(m.mesh, m.faces, organ_support), {true, true, true}, Vec3::Zero()});
        m.support_description = "no body label: organ " + organ_support_text(organ_support);
        finish(m, tissues, meshing.organ_cell_mm);
        return m;
    }
    // Bone: removed; the gel and organs are bonded to its surface (fixed nodes).
    std::vector<std::int32_t> bone_surface;
    if (has_bone) {
        std::vector<char> mark(m.mesh.node_count(), 0);
        for (std::size_t c = 0; c < full.cell_count(); ++c)
            if (roles.bone.count(full.cell_labels[c]))
                for (const auto n : full.cell(c))
                    if (new_of_old[static_cast<std::size_t>(n)] >= 0) mark[static_cast<std::size_t>(new_of_old[static_cast<std::size_t>(n)])] = 1;
        for (std::size_t n = 0; n < mark.size(); ++n)
            if (mark[n]) bone_surface.push_back(static_cast<std::int32_t>(n));
        m.supports.constraints.push_back({"bone", bone_surface, {true, true, true}, Vec3::Zero()});
    }
    // The flat base (the most posterior skin) rests on a frictionless table: y fixed; x, z too when
    // there is no bone to hold the body.
    m.faces = boundary_faces(m.mesh);
    double base_y = -1e300;
    for (const auto& f : m.faces)
        for (int a = 0; a < f.count; ++a) base_y = std::max(base_y, m.mesh.nodes[static_cast<std::size_t>(f.nodes[a])].y());
    std::vector<char> on_base(m.mesh.node_count(), 0);
    for (const auto& f : m.faces)
        if (f.normal.y() > 0.9)
            for (int a = 0; a < f.count; ++a)
                if (m.mesh.nodes[static_cast<std::size_t>(f.nodes[a])].y() > base_y - 0.5 * meshing.facet_mm)
                    on_base[static_cast<std::size_t>(f.nodes[a])] = 1;
    std::vector<std::int32_t> base;
    for (std::size_t n = 0; n < on_base.size(); ++n)
        if (on_base[n]) base.push_back(static_cast<std::int32_t>(n));
    if (base.empty()) fail("ground-truth mesh: the body has no flat posterior base to rest on");
    m.supports.constraints.push_back({"table", base, {!has_bone, true, !has_bone}, Vec3::Zero()});
    m.support_description = fmt::format("{}base (outward normal y > 0.9, within {:.1f} mm of the most posterior skin, {} nodes) on a {} table",
                                        has_bone ? fmt::format("bone removed, its surface fixed ({} nodes); ", bone_surface.size()) : "",
                                        0.5 * meshing.facet_mm, base.size(), has_bone ? "frictionless" : "sticking");
    finish(m, tissues, meshing.organ_cell_mm);
    return m;
}

GroundTruthModel build_organ_model(const GroundTruthModel& body, const LabelRoles& roles, const TissueTable& tissues, const OrganSupport& organ_support)
{
    GroundTruthModel m;
    m.name = "organs";
    std::vector<std::int32_t> new_of_old;
    m.mesh = extract_cells(body.mesh, [&](std::int32_t l) { return roles.is_liver_tissue(l) || roles.kidney.count(l) > 0; }, new_of_old);
    if (m.mesh.cell_count() == 0) fail("ground truth: the body mesh has no organ tetrahedra");
    m.faces = boundary_faces(m.mesh);
    m.supports.constraints.push_back({organ_support.name + "_support", supported_face_nodes(m.mesh, m.faces, organ_support), {true, true, true}, Vec3::Zero()});
    m.support_description = "organs cut out of the body mesh; " + organ_support_text(organ_support);
    finish(m, tissues, body.organ_cell_mm);
    return m;
}

GroundTruthSolve solve_ground_truth_state(const GroundTruthModel& m, Loads loads, int load_steps, const std::string& what)
{
    if (load_steps < 1) fail("{}: load steps {} must be ≥ 1", what, load_steps);
    for (const auto& c : m.supports.constraints) loads.constraints.push_back(c);
    NewtonOptions options;
    options.residual_tolerance = ground_truth_residual_tolerance;
    options.penetration_tolerance_mm = ground_truth_penetration_tolerance_mm;
    // Early multiplier updates and a soft penalty (0.2 × the node's stiffness bound, the
    // multipliers do the rest): measured on the small preset, 7 Newton iterations per load step
    // instead of 20–40 (and no stagnation at 15 mm with ν 0.495).
    options.update_contact_on_stall = true;
    options.contact_penalty_scale = 0.2;
    NewtonSolver solver(*m.model, options);
    solver.set_loads(loads);
    GroundTruthSolve s;
    const auto t0 = std::chrono::steady_clock::now();
    for (int step = 1; step <= load_steps; ++step) {
        NewtonSummary summary;
        try {
            // The load steps report their own progress (a compression can take minutes).
            summary = solver.solve_equilibrium(static_cast<double>(step) / load_steps, [&](double, long iteration) {
                post_progress_note(what, fmt::format("load step {}/{}, Newton iteration {}", step, load_steps, iteration));
                // Ctrl-C / kill between Newton iterations. The compressions are solved in an OpenMP
                // loop whose body catches and hands the exception to the main thread, so this
                // throws even off the main thread (where throw_if_interrupted() does nothing).
                if (const int signal = interrupt_signal()) throw Interrupted(signal, interruption_message(signal));
            });
        } catch (const Interrupted&) {
            post_progress_note(what, "");
            throw;
        } catch (const Error& e) {
            post_progress_note(what, "");
            fail("ground truth for {}: {} (load step {} of {}; the load folds the ground truth's elements: try a smaller depth or a "
                 "larger tool)", what, e.what(), step, load_steps);
        }
        s.newton_iterations += summary.newton_iterations;
        s.contact_updates += summary.contact_updates;
        s.factorisations += summary.factorisations;
        s.load_cuts += summary.load_cuts;
        if (!summary.converged)
            fail("ground truth for {}: no equilibrium at load step {} of {}: {}", what, step, load_steps, summary.message);
        s.worst_residual_ratio = std::max(s.worst_residual_ratio, summary.residual_n / std::max(summary.reference_force_n, 1e-300));
        s.max_penetration_mm = summary.max_penetration_mm;
        logger()->debug("{}: step {}/{}: {} Newton iterations, {} contact updates, {} factorisations; assembly {:.2f} s, factor {:.2f} s, "
                        "solve {:.2f} s, contact {:.2f} s, line search {:.2f} s, total {:.2f} s", what, step, load_steps, summary.newton_iterations,
                        summary.contact_updates, summary.factorisations, summary.assembly_s, summary.factorisation_s, summary.solve_s,
                        summary.contact_s, summary.line_search_s, summary.seconds);
    }
    post_progress_note(what, "");
    s.load_steps = load_steps;
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.displacement_mm = solver.displacement_mm();
    for (std::size_t n = 0; 3 * n + 2 < s.displacement_mm.size(); ++n)
        s.max_displacement_mm = std::max(s.max_displacement_mm, Vec3(s.displacement_mm[3 * n], s.displacement_mm[3 * n + 1],
                                                                     s.displacement_mm[3 * n + 2]).norm());
    return s;
}

CalculixValidation validate_ground_truth_against_calculix(const TissueTable& tissues, std::int32_t gel_label, std::int32_t inclusion_label,
                                                          const std::filesystem::path& work_directory)
{
    if (!calculix_available()) fail("CalculiX validation: ccx (Debian calculix-ccx) is not installed");
    const Tissue* gel = tissues.find(gel_label);
    const Tissue* inclusion = tissues.find(inclusion_label);
    if (!gel || !inclusion) fail("CalculiX validation: labels {} and {} must both be tissues", gel_label, inclusion_label);
    // A 40 × 40 × 24 mm gel block (1 mm voxels) with a spherical inclusion of radius 7 mm.
    LabelVolume block;
    block.geometry.size = {40, 40, 24};
    block.geometry.spacing = Vec3::Ones();
    block.geometry.origin = Vec3::Constant(0.5);
    block.labels.assign(40 * 40 * 24, static_cast<std::uint16_t>(gel_label));
    const Vec3 centre(20, 20, 11);
    for (std::int64_t k = 0; k < 24; ++k)
        for (std::int64_t j = 0; j < 40; ++j)
            for (std::int64_t i = 0; i < 40; ++i)
                if ((Vec3(i + 0.5, j + 0.5, k + 0.5) - centre).norm() < 7.0)
                    block.labels[static_cast<std::size_t>(i + 40 * (j + 40 * k))] = static_cast<std::uint16_t>(inclusion_label);
    TissueTable two;
    two.tissues = {*gel, *inclusion};
    TetMeshingOptions o;
    o.cell_size_mm = {{inclusion_label, 2.5}};
    o.default_cell_size_mm = 4.0;
    o.facet_size_mm = 2.5;
    o.facet_distance_mm = 0.4;
    const VolumeMesh mesh = mesh_labels_tetrahedral(block, o, "CalculiX validation block");
    // Base fixed; the top nodes within 8 mm of the axis pushed down 3 mm (free to slide sideways).
    double top = -1e300, bottom = 1e300;
    for (const auto& x : mesh.nodes) top = std::max(top, x.z()), bottom = std::min(bottom, x.z());
    Loads loads;
    std::vector<std::int32_t> base, punch;
    for (std::size_t n = 0; n < mesh.node_count(); ++n) {
        const Vec3& x = mesh.nodes[n];
        if (x.z() < bottom + 0.3) base.push_back(static_cast<std::int32_t>(n));
        if (x.z() > top - 0.3 && std::hypot(x.x() - 20, x.y() - 20) < 8.0) punch.push_back(static_cast<std::int32_t>(n));
    }
    const double depth = 3.0;
    loads.constraints.push_back({"base", base, {true, true, true}, Vec3::Zero()});
    loads.constraints.push_back({"punch", punch, {false, false, true}, Vec3(0, 0, -depth)});
    TledOptions to;
    to.law = MaterialLaw::mooney_rivlin;
    const TledModel model(mesh, two, to);
    NewtonOptions no;
    no.residual_tolerance = 1e-9;
    NewtonSolver solver(model, no);
    solver.set_loads(loads);
    for (int step = 1; step <= 4; ++step)
        if (!solver.solve_equilibrium(step / 4.0).converged) fail("CalculiX validation: physreg's Newton did not converge");
    const auto ours = solver.displacement_mm();
    std::filesystem::create_directories(work_directory);
    const auto theirs = solve_with_calculix(mesh, two, MaterialLaw::mooney_rivlin, loads, work_directory, "ground_truth_block");
    CalculixValidation v;
    v.relative_rms = relative_rms_difference(ours, theirs);
    for (std::size_t n = 0; n < mesh.node_count(); ++n)
        v.peak_mm = std::max(v.peak_mm, Vec3(theirs[3 * n], theirs[3 * n + 1], theirs[3 * n + 2]).norm());
    v.nodes = mesh.node_count();
    v.cells = mesh.cell_count();
    v.description = fmt::format("40 x 40 x 24 mm gel block with a 7 mm-radius inclusion ({} and {} of this seed), CGAL tetrahedra "
                                "({} nodes, {} cells), base fixed, {} top nodes pushed {} mm down; physreg Newton vs CalculiX C3D4 "
                                "MOONEY-RIVLIN NLGEOM: RMS nodal difference / CalculiX's peak displacement",
                                gel->name, inclusion->name, v.nodes, v.cells, punch.size(), depth);
    return v;
}

} // namespace physreg
