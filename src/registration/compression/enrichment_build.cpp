// SPDX-License-Identifier: GPL-3.0-or-later
// Building the detail enrichment database: the fine and coarse models deformed under every
// condition of a plan, sequences in parallel, depths warm-started, checkpoints for resuming.
#include "physreg/registration/compression/enrichment.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/progress_note.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/thread_governor.hpp"

#include <nlohmann/json.hpp>
#include <omp.h>

#include <atomic>
#include <cmath>
#include <limits>
#include <fstream>
#include <map>
#include <mutex>

namespace physreg {
namespace fs = std::filesystem;

void EnrichmentPlan::validate() const
{
    if (positions.empty()) fail("enrichment plan: no tool position");
    if (orientations < 1) fail("enrichment plan: orientations must be ≥ 1 (got {})", orientations);
    if (!(tilt_deg > 0 && tilt_deg < 60)) fail("enrichment plan: tilt must lie in (0, 60) degrees (got {})", tilt_deg);
    if (!(direction.norm() > 0) || !direction.allFinite()) fail("enrichment plan: the pressing direction must be a non-zero vector");
    if (depths_mm.empty()) fail("enrichment plan: no depth");
    for (std::size_t i = 0; i < depths_mm.size(); ++i)
        if (!(depths_mm[i] > 0) || !std::isfinite(depths_mm[i]) || (i > 0 && !(depths_mm[i] > depths_mm[i - 1])))
            fail("enrichment plan: depths must be positive and increasing (got {} mm at {})", depths_mm[i], i);
    for (const auto& p : positions)
        if (!p.contact_mm.allFinite()) fail("enrichment plan: position {} is not finite", p.name);
}

Vec3 EnrichmentPlan::orientation(int o) const
{
    const Vec3 d = direction.normalized();
    if (o == 0) return d;
    // Tilted by tilt_deg about axes ⟂ d at equal azimuths.
    const Vec3 e1 = (std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitZ()).cross(d).normalized(), e2 = d.cross(e1);
    const double azimuth = 2.0 * M_PI * double(o - 1) / double(std::max(1, orientations - 1));
    const double tilt = tilt_deg * M_PI / 180.0;
    return (std::cos(tilt) * d + std::sin(tilt) * (std::cos(azimuth) * e1 + std::sin(azimuth) * e2)).normalized();
}

std::vector<EnrichmentCondition> EnrichmentPlan::conditions() const
{
    std::vector<EnrichmentCondition> out;
    for (const auto& p : positions)
        for (int o = 0; o < orientations; ++o)
            for (const double depth : depths_mm) out.push_back({p.name, p.contact_mm, orientation(o), depth});
    return out;
}

Indenter condition_tool(const Indenter& shape, const EnrichmentCondition& c, double back_mm)
{
    Indenter tool = shape;
    tool.path = {c.contact_mm - back_mm * c.direction, c.contact_mm + c.depth_mm * c.direction};
    return tool;
}

std::vector<EnrichmentPlan::Position> skin_grid_positions(const LabelVolume& rest_labels, const LabelRoles& roles, const Indenter& tool,
                                                          const Vec3& direction, int columns, int rows)
{
    if (tool.shape != IndenterShape::sphere || !(tool.radius_mm > 0)) fail("skin grid positions: the tool must be a sphere (radius > 0 mm)");
    if (columns < 1 || rows < 1 || columns > 50 || rows > 50) fail("skin grid positions: {} x {} positions (need 1 … 50 each way)", columns, rows);
    if (!(direction.norm() > 0) || !direction.allFinite()) fail("skin grid positions: the pressing direction is zero or not finite");
    const Vec3 d = direction.normalized();
    // Two axes across the pressing direction.
    const Vec3 helper = std::abs(d.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitZ();
    const Vec3 e1 = (helper - helper.dot(d) * d).normalized(), e2 = d.cross(e1);
    const auto& g = rest_labels.geometry;
    const auto& size = g.size;
    auto at = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
        return rest_labels.labels[static_cast<std::size_t>(i + size[0] * (j + size[1] * k))];
    };
    // The liver's extent across the direction; the body's boundary voxels (a background face neighbour).
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    std::vector<Vec3> skin;
    for (std::int64_t k = 0; k < size[2]; ++k)
        for (std::int64_t j = 0; j < size[1]; ++j)
            for (std::int64_t i = 0; i < size[0]; ++i) {
                const auto l = at(i, j, k);
                if (l == 0) continue;
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                if (roles.is_liver_tissue(l)) {
                    const Vec3 c(x.dot(e1), x.dot(e2), x.dot(d));
                    lo = lo.cwiseMin(c), hi = hi.cwiseMax(c);
                }
                const bool boundary = i == 0 || j == 0 || k == 0 || i + 1 == size[0] || j + 1 == size[1] || k + 1 == size[2] || at(i - 1, j, k) == 0 ||
                                      at(i + 1, j, k) == 0 || at(i, j - 1, k) == 0 || at(i, j + 1, k) == 0 || at(i, j, k - 1) == 0 || at(i, j, k + 1) == 0;
                if (boundary) skin.push_back(x);
            }
    if (!(hi.x() >= lo.x())) fail("skin grid positions: no liver label ({}) in the label map", fmt::join(roles.liver, ","));
    const double r = tool.radius_mm;
    std::vector<EnrichmentPlan::Position> out;
    for (int c = 0; c < columns; ++c)
        for (int w = 0; w < rows; ++w) {
            const double fa = columns == 1 ? 0.5 : 0.15 + 0.7 * double(c) / double(columns - 1);
            const double fb = rows == 1 ? 0.5 : 0.15 + 0.7 * double(w) / double(rows - 1);
            const Vec3 p = (lo.x() + fa * (hi.x() - lo.x())) * e1 + (lo.y() + fb * (hi.y() - lo.y())) * e2; // on the line, t = 0
            // First touch of the sphere moving along d: the smallest centre offset t at which a
            // skin point lies on the sphere, t = s − √(r² − ρ²) over skin points within r of the line.
            double first = std::numeric_limits<double>::infinity();
            for (const auto& x : skin) {
                const Vec3 v = x - p;
                const double s = v.dot(d), rho2 = (v - s * d).squaredNorm();
                if (rho2 <= r * r) first = std::min(first, s - std::sqrt(r * r - rho2));
            }
            if (!std::isfinite(first)) fail("skin grid positions: the line through ({:.1f}, {:.1f}, {:.1f}) mm misses the body", p.x(), p.y(), p.z());
            out.push_back({fmt::format("G{}{}", c + 1, w + 1), p + first * d});
        }
    return out;
}

std::string enrichment_model_json(const LiverModel& fine, const LiverModel& coarse)
{
    const auto& p = fine.parameters;
    nlohmann::json j = {{"variant", to_string(p.variant)},
                        {"region", to_string(p.region)},
                        {"body_young_pa", p.body_young_pa},
                        {"k_c_s_t_n_per_m", p.coupling.parenchyma_tumour_n_per_m},
                        {"k_c_s_v_n_per_m", p.coupling.parenchyma_vessel_n_per_m},
                        {"young_modulus_pa", {{"parenchyma", p.parenchyma_young_pa}, {"tumour", p.tumour_young_pa}, {"vessel", p.vessel_young_pa}}},
                        {"poisson_ratio", p.poisson_ratio},
                        {"fine_grid", {p.grid[0], p.grid[1], p.grid[2]}},
                        {"coarse_grid", {coarse.parameters.grid[0], coarse.parameters.grid[1], coarse.parameters.grid[2]}},
                        {"mls_support_radius_cells", p.support_radius_cells}};
    return j.dump();
}

void check_database_fits(const EnrichmentDatabase& db, const LiverModel& fine, const LiverModel& coarse, const std::string& what)
{
    if (db.fine_fingerprint != fine.fingerprint || db.fine_nodes != fine.mesh.node_count())
        fail("{}: built for another fine mesh (fingerprint {}, this model {})", what, db.fine_fingerprint, fine.fingerprint);
    if (db.coarse_fingerprint != coarse.fingerprint || db.coarse_nodes != coarse.mesh.node_count())
        fail("{}: built for another coarse mesh (fingerprint {}, this model {})", what, db.coarse_fingerprint, coarse.fingerprint);
    const std::string mine = enrichment_model_json(fine, coarse);
    if (nlohmann::json::parse(db.model_json) != nlohmann::json::parse(mine))
        fail("{}: built for other model parameters (tissue table or coupling): database {}, this model {}", what, db.model_json, mine);
}

namespace {

bool same_condition(const EnrichmentCondition& a, const EnrichmentCondition& b)
{
    return a.position == b.position && (a.contact_mm - b.contact_mm).norm() < 1e-9 && (a.direction - b.direction).norm() < 1e-12 &&
           std::abs(a.depth_mm - b.depth_mm) < 1e-12;
}

// One sequence: a position and an orientation through every depth, both models warm-started.
EnrichmentDatabase build_sequence(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                  const Indenter& shape, const std::vector<EnrichmentCondition>& conditions, const PredictionOptions& options)
{
    EnrichmentDatabase part;
    part.fine_nodes = fine.mesh.node_count();
    part.coarse_nodes = coarse.mesh.node_count();
    // The tool passes every depth of the sequence in turn: one path, one load level per depth.
    const double back = 2.0 * coarse.cell_size_mm.maxCoeff();
    const Vec3 d = conditions.front().direction, contact = conditions.front().contact_mm;
    Indenter tool = shape;
    tool.path = {contact - back * d};
    for (const auto& c : conditions) tool.path.push_back(contact + c.depth_mm * d);
    const double steps = double(conditions.size());
    auto solver_for = [&](const LiverModel& m) {
        auto solver = std::make_unique<StaticSolver>(*m.tled, StaticSolverOptions{options.method, options.equilibrium, options.newton});
        solver->set_coupling(m.coupling.empty() ? nullptr : &m.coupling);
        Loads loads;
        loads.constraints = m.supports();
        loads.indenters.push_back(tool);
        solver->set_loads(loads);
        return solver;
    };
    auto fine_solver = solver_for(fine), coarse_solver = solver_for(coarse);
    // A sequence takes minutes on the body model and reports as a whole: its depths post notes
    // that the progress display shows between those reports (the ground truth's load steps do the same).
    const std::string note = fmt::format("enrichment sequence {}", conditions.front().position);
    double previous_depth = -back;
    for (std::size_t i = 0; i < conditions.size(); ++i) {
        const double travel = conditions[i].depth_mm - previous_depth;
        previous_depth = conditions[i].depth_mm;
        auto solve = [&](StaticSolver& solver, const LiverModel& m, const char* level) {
            const long ramp = std::max<long>(options.equilibrium.ramp_iterations,
                                             std::lround(std::ceil(1.875 * travel / (options.tool_speed_per_cell * m.cell_size_mm.minCoeff()))));
            const std::string what = fmt::format("enrichment condition {} {:.2f} mm, {} model", conditions[i].position, conditions[i].depth_mm, level);
            StaticSolveResult s;
            post_progress_note(note, fmt::format("depth {:.1f} mm ({} of {}), {} model", conditions[i].depth_mm, i + 1, conditions.size(), level));
            try {
                s = solver.solve(double(i + 1) / steps, ramp);
            } catch (const Error& e) {
                post_progress_note(note, "");
                fail("{}: {} (drop this depth or position from the plan, or lower --tool-speed)", what, e.what());
            }
            if (!s.converged) fail("{}: {}", what, s.message);
            return solver.displacement_mm();
        };
        const auto fu = solve(*fine_solver, fine, "fine");
        const auto cu = solve(*coarse_solver, coarse, "coarse");
        part.conditions.push_back(conditions[i]);
        part.coarse_displacement.emplace_back(cu.begin(), cu.end());
        part.weights.push_back(enrichment_weights(coarse.mesh, cu, fine_nodes, fine.mesh.nodes, fu));
    }
    post_progress_note(note, "");
    return part;
}

} // namespace

EnrichmentDatabase build_enrichment_database(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                             const Indenter& tool_shape, const EnrichmentPlan& plan, const EnrichmentBuildOptions& options)
{
    plan.validate();
    if (options.ranks < 1 || options.rank < 0 || options.rank >= options.ranks) fail("enrichment build: rank {} of {}", options.rank, options.ranks);
    if (fine_nodes.size() != fine.mesh.node_count()) fail("enrichment build: {} embeddings for {} fine nodes", fine_nodes.size(), fine.mesh.node_count());
    const auto all = plan.conditions();
    const std::size_t per_sequence = plan.depths_mm.size(), sequences = plan.sequences();
    std::vector<std::size_t> mine;
    for (std::size_t s = 0; s < sequences; ++s)
        if (static_cast<int>(s % static_cast<std::size_t>(options.ranks)) == options.rank) mine.push_back(s);
    const std::string model = enrichment_model_json(fine, coarse);
    auto checkpoint = [&](std::size_t s) { return options.checkpoint_directory / fmt::format("sequence_{:05d}.phe", s); };
    if (!options.checkpoint_directory.empty()) fs::create_directories(options.checkpoint_directory);
    std::vector<EnrichmentDatabase> parts(mine.size());
    std::vector<std::string> errors(mine.size());
    std::atomic<std::size_t> done{0}, resumed{0};
    std::mutex progress_lock;
    // One sequence per thread; those left after the last whole round on the full team each.
    for_each_task_packed(mine.size(), [&](std::size_t i) {
        const std::size_t s = mine[i];
        const std::vector<EnrichmentCondition> conditions(all.begin() + static_cast<long>(s * per_sequence),
                                                          all.begin() + static_cast<long>((s + 1) * per_sequence));
        try {
            bool have = false;
            if (!options.checkpoint_directory.empty() && fs::exists(checkpoint(s))) {
                // Resume: a finished sequence of an earlier run, if it is for these meshes and conditions.
                try {
                    EnrichmentDatabase saved = read_enrichment_database(checkpoint(s));
                    bool same = saved.fine_fingerprint == fine.fingerprint && saved.coarse_fingerprint == coarse.fingerprint &&
                                saved.model_json == model && saved.conditions.size() == conditions.size();
                    for (std::size_t k = 0; same && k < conditions.size(); ++k) same = same_condition(saved.conditions[k], conditions[k]);
                    if (same) {
                        parts[i] = std::move(saved);
                        have = true;
                        ++resumed;
                    } else {
                        logger()->warn("checkpoint '{}' is for another model or plan; rebuilding it", checkpoint(s).string());
                    }
                } catch (const Error& e) {
                    logger()->warn("checkpoint '{}' unreadable ({}); rebuilding it", checkpoint(s).string(), e.what());
                }
            }
            if (!have) {
                parts[i] = build_sequence(fine, coarse, fine_nodes, tool_shape, conditions, options.prediction);
                parts[i].fine_fingerprint = fine.fingerprint;
                parts[i].coarse_fingerprint = coarse.fingerprint;
                parts[i].model_json = model;
                if (!options.checkpoint_directory.empty()) write_enrichment_database(checkpoint(s), parts[i]);
            }
        } catch (const std::exception& e) {
            errors[i] = e.what();
        }
        const std::size_t finished = ++done;
        if (options.progress) {
            std::lock_guard<std::mutex> lock(progress_lock);
            options.progress(double(finished) / double(mine.size()),
                             fmt::format("sequence {} ({} of {} here; {} conditions each)", conditions.front().position, finished, mine.size(),
                                         per_sequence));
        }
    });
    for (const auto& e : errors)
        if (!e.empty()) fail("enrichment build: {}", e);
    if (resumed > 0) logger()->info("enrichment build: {} of {} sequences resumed from checkpoints", resumed.load(), mine.size());
    EnrichmentDatabase out;
    out.fine_fingerprint = fine.fingerprint;
    out.coarse_fingerprint = coarse.fingerprint;
    out.model_json = model;
    out.fine_nodes = fine.mesh.node_count();
    out.coarse_nodes = coarse.mesh.node_count();
    for (auto& p : parts)
        for (std::size_t k = 0; k < p.conditions.size(); ++k) {
            out.conditions.push_back(p.conditions[k]);
            out.coarse_displacement.push_back(std::move(p.coarse_displacement[k]));
            out.weights.push_back(std::move(p.weights[k]));
        }
    return out;
}

EnrichmentDatabase merge_enrichment_parts(const std::vector<EnrichmentDatabase>& parts, const EnrichmentPlan& plan)
{
    if (parts.empty()) fail("enrichment merge: no parts");
    EnrichmentDatabase out;
    out.fine_fingerprint = parts.front().fine_fingerprint;
    out.coarse_fingerprint = parts.front().coarse_fingerprint;
    out.model_json = parts.front().model_json;
    out.fine_nodes = parts.front().fine_nodes;
    out.coarse_nodes = parts.front().coarse_nodes;
    for (const auto& p : parts)
        if (p.fine_fingerprint != out.fine_fingerprint || p.coarse_fingerprint != out.coarse_fingerprint || p.model_json != out.model_json)
            fail("enrichment merge: parts were built for different models");
    for (const auto& c : plan.conditions()) {
        const EnrichmentDatabase* from = nullptr;
        std::size_t at = 0;
        for (const auto& p : parts)
            for (std::size_t k = 0; k < p.conditions.size(); ++k)
                if (same_condition(p.conditions[k], c)) {
                    if (from) fail("enrichment merge: condition {} {:.2f} mm appears twice", c.position, c.depth_mm);
                    from = &p;
                    at = k;
                }
        if (!from) fail("enrichment merge: condition {} {:.2f} mm is missing", c.position, c.depth_mm);
        out.conditions.push_back(from->conditions[at]);
        out.coarse_displacement.push_back(from->coarse_displacement[at]);
        out.weights.push_back(from->weights[at]);
    }
    return out;
}

} // namespace physreg
