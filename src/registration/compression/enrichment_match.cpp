// SPDX-License-Identifier: GPL-3.0-or-later
// Run-time side of the detail enrichment: which stored conditions fit a new deformation.
#include "physreg/registration/compression/enrichment.hpp"

#include "physreg/core/error.hpp"

#include <chrono>
#include <Eigen/Dense>
#include <optional>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace physreg {

EnrichmentMatching parse_enrichment_matching(const std::string& text)
{
    if (text == "parameters") return EnrichmentMatching::parameters;
    if (text == "field") return EnrichmentMatching::field;
    fail("matching '{}' is not one of parameters, field", text);
}

double condition_distance(const EnrichmentCondition& a, const EnrichmentCondition& b)
{
    const double angle = std::acos(std::clamp(a.direction.normalized().dot(b.direction.normalized()), -1.0, 1.0));
    return (a.contact_mm - b.contact_mm).norm() + std::abs(a.depth_mm - b.depth_mm) + 10.0 * angle;
}

void EnrichmentBlend::validate(const std::string& what) const
{
    if (conditions < 1) fail("{}: blend size must be ≥ 1 (got {})", what, conditions);
    if (!(detail_length_mm >= 0.0)) fail("{}: detail length must be ≥ 0 mm (got {})", what, detail_length_mm);
}

double EnrichmentBlend::detail_share(double nearest_distance) const
{
    if (std::isinf(detail_length_mm)) return 1.0;
    if (nearest_distance <= 1e-12) return 1.0;
    if (detail_length_mm == 0.0) return 0.0;
    const double r = nearest_distance / detail_length_mm;
    return 1.0 / (1.0 + r * r);
}

namespace {

// How far (mm) a point lies outside the convex hull of `points` (0 inside), all in one plane's 2-D
// coordinates. A hand-written monotone chain: a few dozen points, no need for CGAL here.
double outside_hull_mm(std::vector<Eigen::Vector2d> points, const Eigen::Vector2d& q)
{
    std::sort(points.begin(), points.end(), [](const auto& a, const auto& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
    points.erase(std::unique(points.begin(), points.end(), [](const auto& a, const auto& b) { return (a - b).norm() < 1e-9; }), points.end());
    auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
    };
    auto segment_distance = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
        const Eigen::Vector2d ab = b - a;
        const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
        return (a + t * ab - p).norm();
    };
    if (points.size() == 1) return (points.front() - q).norm();
    std::vector<Eigen::Vector2d> hull(2 * points.size());
    std::size_t k = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
        while (k >= 2 && cross(hull[k - 2], hull[k - 1], points[i]) <= 0) --k;
        hull[k++] = points[i];
    }
    for (std::size_t i = points.size() - 1, t = k + 1; i > 0; --i) {
        while (k >= t && cross(hull[k - 2], hull[k - 1], points[i - 1]) <= 0) --k;
        hull[k++] = points[i - 1];
    }
    hull.resize(k - 1); // counter-clockwise, first point not repeated
    double nearest = 1e300;
    bool inside = hull.size() >= 3;
    for (std::size_t i = 0; i < hull.size(); ++i) {
        const auto& a = hull[i];
        const auto& b = hull[(i + 1) % hull.size()];
        nearest = std::min(nearest, segment_distance(a, b, q));
        if (cross(a, b, q) < 0) inside = false;
    }
    return inside ? 0.0 : nearest;
}

double field_distance(const std::vector<float>& stored, const std::vector<double>& u)
{
    double sum = 0.0;
    for (std::size_t k = 0; k < u.size(); ++k) sum += (double(stored[k]) - u[k]) * (double(stored[k]) - u[k]);
    return std::sqrt(sum / double(std::max<std::size_t>(1, u.size() / 3)));
}

EnrichmentMatch nearest(const std::vector<double>& distance, int k, std::size_t excluded)
{
    std::vector<std::size_t> order;
    for (std::size_t t = 0; t < distance.size(); ++t)
        if (t != excluded) order.push_back(t);
    const std::size_t take = std::min<std::size_t>(static_cast<std::size_t>(std::max(1, k)), order.size());
    std::partial_sort(order.begin(), order.begin() + static_cast<long>(take), order.end(),
                      [&](std::size_t a, std::size_t b) { return distance[a] < distance[b] || (distance[a] == distance[b] && a < b); });
    EnrichmentMatch m;
    for (std::size_t i = 0; i < take; ++i) {
        m.conditions.push_back(order[i]);
        m.distances.push_back(distance[order[i]]);
    }
    // Inverse-distance blend; an exact hit takes everything.
    if (m.distances.front() <= 1e-12) {
        m.blend.assign(take, 0.0);
        m.blend.front() = 1.0;
    } else {
        double total = 0.0;
        for (const double d : m.distances) total += 1.0 / d;
        for (const double d : m.distances) m.blend.push_back((1.0 / d) / total);
    }
    return m;
}

} // namespace

EnrichmentMatch match_enrichment(const EnrichmentDatabase& db, EnrichmentMatching how, const EnrichmentBlend& blend, const EnrichmentCondition* query,
                                 const std::vector<double>& coarse_u)
{
    if (db.conditions.empty()) fail("enrichment database holds no condition");
    blend.validate("enrichment");
    std::vector<double> distance(db.conditions.size());
    if (how == EnrichmentMatching::parameters) {
        if (!query) fail("enrichment: matching by parameters needs the tool's position, direction and depth");
        for (std::size_t t = 0; t < distance.size(); ++t) distance[t] = condition_distance(db.conditions[t], *query);
    } else {
        if (coarse_u.size() != 3 * db.coarse_nodes) fail("enrichment: {} coarse values for a database of {} coarse nodes", coarse_u.size(), db.coarse_nodes);
        for (std::size_t t = 0; t < distance.size(); ++t) distance[t] = field_distance(db.coarse_displacement[t], coarse_u);
    }
    EnrichmentMatch m = nearest(distance, blend.conditions, distance.size());
    m.detail = blend.detail_share(m.distances.front());
    if (query) {
        // Range: the stored entry points' hull seen along the query's direction, the stored depths
        // at the nearest entry point and direction, and how far the directions differ.
        const auto& near = db.conditions[m.conditions.front()];
        double lo = 1e300, hi = -1e300;
        for (const auto& c : db.conditions)
            if (c.position == near.position && (c.direction - near.direction).norm() < 1e-9) lo = std::min(lo, c.depth_mm), hi = std::max(hi, c.depth_mm);
        const Vec3 axis = query->direction.normalized();
        const Vec3 e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
        std::vector<Eigen::Vector2d> entries;
        m.nearest_position_mm = 1e300;
        double widest_tilt = 0.0, angle = 180.0;
        for (const auto& c : db.conditions) {
            entries.emplace_back(c.contact_mm.dot(e1), c.contact_mm.dot(e2));
            m.nearest_position_mm = std::min(m.nearest_position_mm, (c.contact_mm - query->contact_mm).norm());
            angle = std::min(angle, std::acos(std::clamp(axis.dot(c.direction.normalized()), -1.0, 1.0)) * 180.0 / M_PI);
            widest_tilt = std::max(widest_tilt, std::acos(std::clamp(near.direction.normalized().dot(c.direction.normalized()), -1.0, 1.0)) * 180.0 / M_PI);
        }
        const double out = outside_hull_mm(entries, {query->contact_mm.dot(e1), query->contact_mm.dot(e2)});
        std::vector<std::string> notes;
        if (query->depth_mm > hi + 1e-9) notes.push_back(fmt::format("depth {:.2f} mm is {:.2f} mm beyond the deepest stored ({:.2f} mm)", query->depth_mm, query->depth_mm - hi, hi));
        if (query->depth_mm < lo - 1e-9) notes.push_back(fmt::format("depth {:.2f} mm is {:.2f} mm short of the shallowest stored ({:.2f} mm)", query->depth_mm, lo - query->depth_mm, lo));
        if (out > 5.0)
            notes.push_back(fmt::format("the tool enters {:.1f} mm outside the stored positions' span ({:.1f} mm from the nearest, {})", out,
                                        m.nearest_position_mm, near.position));
        if (angle > std::max(5.0, widest_tilt + 1e-6)) notes.push_back(fmt::format("the direction differs by {:.1f}° from the nearest stored one", angle));
        if (!notes.empty()) {
            m.outside_range = true;
            m.range_note = fmt::format("{}", fmt::join(notes, "; "));
        }
    }
    return m;
}

std::vector<float> blended_weights(const EnrichmentDatabase& db, const EnrichmentMatch& match, const std::vector<NodeEmbedding>* fine_nodes)
{
    if (match.conditions.empty()) fail("enrichment: empty match");
    const bool mixed = match.detail < 1.0;
    if (mixed && (!fine_nodes || 8 * fine_nodes->size() != db.weights[match.conditions.front()].size()))
        fail("enrichment: a detail share below 1 needs the fine nodes' embedding ({} for {} fine nodes)", fine_nodes ? fine_nodes->size() : 0,
             db.fine_nodes);
    std::vector<double> sum(db.weights[match.conditions.front()].size(), 0.0);
    for (std::size_t i = 0; i < match.conditions.size(); ++i) {
        const auto& w = db.weights[match.conditions[i]];
        for (std::size_t q = 0; q < w.size(); ++q) sum[q] += match.blend[i] * double(w[q]);
    }
    if (mixed)
        for (std::size_t j = 0; j < fine_nodes->size(); ++j) {
            const auto n = hex_shape_functions((*fine_nodes)[j].natural);
            for (std::size_t k = 0; k < 8; ++k) sum[8 * j + k] = match.detail * sum[8 * j + k] + (1.0 - match.detail) * n[k];
        }
    return {sum.begin(), sum.end()};
}

int choose_blend_size(const EnrichmentDatabase& db, const VolumeMesh& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                      const std::vector<Vec3>& fine_rest, int max_k, std::vector<double>* errors_mm)
{
    if (db.conditions.size() < 2) {
        if (errors_mm) errors_mm->assign(1, 0.0);
        return 1;
    }
    max_k = std::max(1, std::min<int>(max_k, static_cast<int>(db.conditions.size()) - 1));
    std::vector<double> error(static_cast<std::size_t>(max_k), 0.0);
    for (std::size_t t = 0; t < db.conditions.size(); ++t) {
        const std::vector<double> cu(db.coarse_displacement[t].begin(), db.coarse_displacement[t].end());
        const auto truth = synthesize_fine_displacement(coarse, cu, fine_nodes, fine_rest, db.weights[t]);
        std::vector<double> distance(db.conditions.size());
        for (std::size_t s = 0; s < distance.size(); ++s) distance[s] = field_distance(db.coarse_displacement[s], cu);
        for (int k = 1; k <= max_k; ++k) {
            EnrichmentMatch m = nearest(distance, k, t);
            const auto u = synthesize_fine_displacement(coarse, cu, fine_nodes, fine_rest, blended_weights(db, m));
            double e = 0.0;
            for (std::size_t j = 0; j < fine_rest.size(); ++j)
                e += Vec3(u[3 * j] - truth[3 * j], u[3 * j + 1] - truth[3 * j + 1], u[3 * j + 2] - truth[3 * j + 2]).norm();
            error[static_cast<std::size_t>(k - 1)] += e / double(fine_rest.size()) / double(db.conditions.size());
        }
    }
    if (errors_mm) *errors_mm = error;
    return 1 + static_cast<int>(std::min_element(error.begin(), error.end()) - error.begin());
}

double choose_detail_length(const EnrichmentDatabase& db, const VolumeMesh& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                            const std::vector<Vec3>& fine_rest, EnrichmentMatching how, int k, std::vector<std::pair<double, double>>* errors_mm,
                            const std::vector<std::int32_t>& scored)
{
    std::vector<std::size_t> nodes;
    for (const auto n : scored) {
        if (n < 0 || static_cast<std::size_t>(n) >= fine_rest.size()) fail("detail length: scored fine node {} out of range", n);
        nodes.push_back(static_cast<std::size_t>(n));
    }
    if (nodes.empty())
        for (std::size_t j = 0; j < fine_rest.size(); ++j) nodes.push_back(j);
    const double inf = std::numeric_limits<double>::infinity();
    const std::vector<double> lengths{0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, inf};
    auto same_sequence = [&](std::size_t a, std::size_t b) {
        return db.conditions[a].position == db.conditions[b].position && (db.conditions[a].direction - db.conditions[b].direction).norm() < 1e-9;
    };
    std::vector<double> error(lengths.size(), 0.0);
    std::size_t tested = 0;
    for (std::size_t t = 0; t < db.conditions.size(); ++t) {
        std::vector<double> distance(db.conditions.size(), inf);
        const std::vector<double> cu(db.coarse_displacement[t].begin(), db.coarse_displacement[t].end());
        bool any = false;
        for (std::size_t s = 0; s < distance.size(); ++s) {
            if (same_sequence(s, t)) continue;
            distance[s] = how == EnrichmentMatching::parameters ? condition_distance(db.conditions[s], db.conditions[t])
                                                                : field_distance(db.coarse_displacement[s], cu);
            any = true;
        }
        if (!any) continue;
        ++tested;
        const auto truth = synthesize_fine_displacement(coarse, cu, fine_nodes, fine_rest, db.weights[t]);
        EnrichmentMatch m = nearest(distance, k, t);
        // nearest() takes the k smallest; the same sequence's conditions carry ∞ and are dropped.
        while (!m.conditions.empty() && std::isinf(m.distances.back())) m.conditions.pop_back(), m.distances.pop_back();
        double total = 0.0;
        m.blend.clear();
        for (const double d : m.distances) total += 1.0 / std::max(d, 1e-12);
        for (const double d : m.distances) m.blend.push_back((1.0 / std::max(d, 1e-12)) / total);
        for (std::size_t l = 0; l < lengths.size(); ++l) {
            m.detail = EnrichmentBlend(k, lengths[l]).detail_share(m.distances.front());
            const auto u = synthesize_fine_displacement(coarse, cu, fine_nodes, fine_rest, blended_weights(db, m, &fine_nodes));
            double e = 0.0;
            for (const std::size_t j : nodes)
                e += Vec3(u[3 * j] - truth[3 * j], u[3 * j + 1] - truth[3 * j + 1], u[3 * j + 2] - truth[3 * j + 2]).norm();
            error[l] += e / double(nodes.size());
        }
    }
    if (errors_mm) errors_mm->clear();
    if (tested == 0) return inf;
    for (auto& e : error) e /= double(tested);
    if (errors_mm)
        for (std::size_t l = 0; l < lengths.size(); ++l) errors_mm->push_back({lengths[l], error[l]});
    return lengths[static_cast<std::size_t>(std::min_element(error.begin(), error.end()) - error.begin())];
}

namespace {

// Run-time steps 2–4: matched conditions, their blended weights, every fine node synthesised.
std::vector<double> match_and_synthesize(const EnrichmentDatabase& db, EnrichmentMatching how, const EnrichmentBlend& blend, const EnrichmentCondition& query,
                                         const LiverModel& coarse, const std::vector<double>& coarse_u, const std::vector<NodeEmbedding>& fine_nodes,
                                         const LiverModel& fine, EnrichmentMatch& match)
{
    match = match_enrichment(db, how, blend, &query, coarse_u);
    return synthesize_fine_displacement(coarse.mesh, coarse_u, fine_nodes, fine.mesh.nodes, blended_weights(db, match, &fine_nodes));
}

} // namespace

CoarseToFinePrediction predict_coarse_to_fine(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                                              const EnrichmentDatabase& db, const Indenter& tool, const LandmarkSet& rest_landmarks,
                                              EnrichmentMatching how, const EnrichmentBlend& blend, const PredictionOptions& options,
                                              const std::string& what)
{
    CoarseToFinePrediction out;
    // The coarse model's cells are too coarse to hold the skin under the tool (measured: a 15 mm
    // sphere 10 mm past first contact ends inside the small preset's coarse model); the detail the
    // database adds is what carries it, so its passage is not an error here.
    PredictionOptions coarse_options = options;
    coarse_options.refuse_tool_passage = false;
    const CompressionPrediction c = predict_compression(coarse, tool, {}, coarse_options, what + " (coarse model)");
    out.coarse_u = c.displacement_mm;
    out.iterations = c.iterations;
    out.coarse_seconds = c.seconds;
    const auto t0 = std::chrono::steady_clock::now();
    const EnrichmentCondition query{"", tool.path.front(), (tool.path.back() - tool.path.front()).normalized(),
                                    (tool.path.back() - tool.path.front()).norm()};
    out.fine_u = match_and_synthesize(db, how, blend, query, coarse, out.coarse_u, fine_nodes, fine, out.match);
    out.synthesis_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out.landmarks = move_landmarks(fine, out.fine_u, rest_landmarks);
    return out;
}

TrackingRun track_compression(const LiverModel& fine, const LiverModel& coarse, const std::vector<NodeEmbedding>& fine_nodes,
                              const EnrichmentDatabase& db, const Indenter& tool, const LandmarkSet& rest_landmarks, int steps,
                              EnrichmentMatching how, const EnrichmentBlend& blend, const PredictionOptions& options, const std::string& what,
                              const std::function<void(int)>& on_step, bool high_resolution)
{
    if (steps < 1) fail("{}: steps must be ≥ 1 (got {})", what, steps);
    using clock = std::chrono::steady_clock;
    const Vec3 start = tool.path.front(), end = tool.path.back();
    const double depth = (end - start).norm();
    const Vec3 d = (end - start) / depth;
    std::optional<CompressionTracker> high;
    if (high_resolution) high.emplace(fine, tool, options);
    CompressionTracker low(coarse, tool, options);
    TrackingRun run;
    for (int s = 1; s <= steps; ++s) {
        const Vec3 position = start + depth * double(s) / double(steps) * d;
        const std::string step = fmt::format("{} step {}", what, s);
        if (high) {
            const auto h = high->move_to(position, step + " (high resolution)");
            run.high_resolution_ms.push_back(1e3 * h.seconds);
            run.high_resolution_iterations.push_back(h.iterations);
        }
        const auto t0 = clock::now();
        const auto l = low.move_to(position, step + " (coarse)");
        const auto cu = low.displacement_mm();
        const auto t1 = clock::now();
        const EnrichmentCondition query{"", start, d, depth * double(s) / double(steps)};
        run.coarse_to_fine_u = match_and_synthesize(db, how, blend, query, coarse, cu, fine_nodes, fine, run.last_match);
        run.coarse_to_fine_landmarks = move_landmarks(fine, run.coarse_to_fine_u, rest_landmarks);
        const auto t2 = clock::now();
        run.coarse_to_fine_ms.push_back(1e3 * std::chrono::duration<double>(t2 - t0).count());
        run.coarse_solve_ms.push_back(1e3 * std::chrono::duration<double>(t1 - t0).count());
        run.synthesis_ms.push_back(1e3 * std::chrono::duration<double>(t2 - t1).count());
        run.coarse_iterations.push_back(l.iterations);
        if (on_step) on_step(s);
    }
    if (high) {
        run.high_resolution_u = high->displacement_mm();
        run.high_resolution_landmarks = move_landmarks(fine, run.high_resolution_u, rest_landmarks);
    }
    return run;
}

} // namespace physreg
