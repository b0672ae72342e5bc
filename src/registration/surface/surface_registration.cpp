// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/surface_registration.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/interrupt.hpp"
#include "physreg/core/log.hpp"
#include "physreg/evaluation/surface_distance.hpp"
#include "physreg/mechanics/forms/mechanics_forms.hpp"
#include "physreg/registration/surface/surface_model.hpp"
#include "registration/detail/principal_axes.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <set>
#include <chrono>
#include <cmath>
#include <exception>
#include <optional>
#include <fmt/format.h>

namespace physreg {

namespace {
double seconds_since(std::chrono::steady_clock::time_point start)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void mark_used(const std::vector<SurfacePair>& pairs, const LabelledTriangles& source, std::vector<std::uint8_t>& used)
{
    std::fill(used.begin(), used.end(), 0);
    for (const auto& p : pairs)
        for (auto node : source.triangles[static_cast<std::size_t>(p.triangle)]) used[static_cast<std::size_t>(node)] = 1;
}
} // namespace

BackwardEulerOptions SurfaceRegistrationOptions::paper001_dynamics()
{
    BackwardEulerOptions o;
    o.time_step_s = 0.1;
    o.rayleigh_mass_per_s = 0.1;
    o.rayleigh_stiffness_s = 0.1;
    o.mass = MassKind::lumped;
    o.tangent = TangentUpdate::stale;
    o.rotated_corotational_tangent = true;
    o.max_newton_iterations = 20;
    o.residual_tolerance = 1e-4;
    return o;
}

void SurfaceRegistrationOptions::validate() const
{
    matching.validate();
    force.validate();
    dynamics.validate();
    if (schedules.empty()) fail("surface registration: no stiffness schedule");
    for (const auto& [label, s] : schedules) s.validate(fmt::format("surface registration: schedule of label {}", label));
    if (!(plateau_tolerance_mm > 0 && std::isfinite(plateau_tolerance_mm)))
        fail("surface registration: plateau tolerance {} mm must be > 0", plateau_tolerance_mm);
    if (!(plateau_rms_fraction >= 0 && plateau_rms_fraction <= 1))
        fail("surface registration: plateau rms fraction {} must lie in [0, 1] (0: off)", plateau_rms_fraction);
    if (newton_iterations_per_step < 0) fail("surface registration: Newton iterations per step {} must be ≥ 0", newton_iterations_per_step);
    if (max_steps_per_plateau < 1) fail("surface registration: max steps per plateau {} must be ≥ 1", max_steps_per_plateau);
    if (!(support_stiffness_n_per_mm >= 0 && std::isfinite(support_stiffness_n_per_mm)))
        fail("surface registration: support stiffness {} N/mm must be ≥ 0 (0: held)", support_stiffness_n_per_mm);
    for (const auto node : fixed_nodes)
        if (node < 0) fail("surface registration: support node {} is not a node id", node);
    for (const auto& s : partial_supports)
        for (const auto node : s.nodes)
            if (node < 0) fail("surface registration: support '{}' node {} is not a node id", s.name, node);
}

std::map<std::int32_t, AnnealingSchedule> paper001_schedules(double k_max_n)
{
    return {{feature_none, {0.0, k_max_n, 10, 3.0}},
            {feature_umbilical_notch, {0.1 * k_max_n, k_max_n, 2, 3.0}},
            {feature_anterior_margin, {0.1 * k_max_n, k_max_n, 4, 3.0}}};
}

double pair_stiffness_n(double traction_ratio, double young_modulus_pa, double spacing_mm)
{
    if (!(traction_ratio > 0 && std::isfinite(traction_ratio))) fail("surface registration: traction ratio {} must be > 0", traction_ratio);
    if (!(young_modulus_pa > 0 && std::isfinite(young_modulus_pa))) fail("surface registration: Young's modulus {} Pa must be > 0", young_modulus_pa);
    if (!(spacing_mm > 0 && std::isfinite(spacing_mm))) fail("surface registration: point spacing {} mm must be > 0 (a cloud of distinct points)", spacing_mm);
    return traction_ratio * young_modulus_pa * 1e-6 * spacing_mm * spacing_mm * std::sqrt(3.0) / 2.0;
}

SurfaceRegistrationResult register_surface_biomechanical(const TledModel& model, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                                         const SurfaceRegistrationOptions& options,
                                                         const std::function<void(double, const std::string&)>& progress)
{
    const auto start = std::chrono::steady_clock::now();
    options.validate();
    if (model.options().law != MaterialLaw::corotational)
        fail("surface registration: the model must use the co-rotational law (paper 001's linear co-rotational tetrahedra)");
    for (auto label : cloud.labels)
        if (!options.schedules.count(label)) fail("surface registration: cloud label {} has no stiffness schedule", label);

    BackwardEulerOptions dynamics = options.dynamics;
    dynamics.fixed_newton_iterations = options.newton_iterations_per_step;
    BackwardEuler integrator(model, dynamics, options.coupling, options.structures);
    const std::size_t n = 3 * model.node_count();
    const std::vector<double>& rest = model.rest_positions();
    SurfaceRegistrationResult result;
    result.node_used.assign(model.node_count(), 0);
    const int plateaus = plateau_count(options.schedules);
    std::vector<double> x(n), forces(n), stiffness(n), previous(n);
    std::vector<SurfacePair> pairs;
    // The state at the end of the last plateau that completed: what is kept when a later plateau's
    // forces fold an element (issue 46: numerical trouble backs the method off, it never ends the run).
    std::vector<double> last_good(n, 0.0);
    // Elastic supports: springs to rest at the support nodes (a Form, mechanics/forms).
    // Where pair forces may act (the tool's contact region); 1 everywhere without one.
    std::vector<std::uint8_t> may_load(model.node_count(), options.load_nodes.empty() ? 1 : 0);
    for (const auto node : options.load_nodes) {
        if (node < 0 || static_cast<std::size_t>(node) >= model.node_count()) fail("surface registration: load node {} is not a model node", node);
        may_load[static_cast<std::size_t>(node)] = 1;
    }
    const SpringForm elastic_supports(model.node_count(), options.support_stiffness_n_per_mm > 0 ? options.fixed_nodes : std::vector<std::int32_t>{},
                                      options.support_stiffness_n_per_mm);
    // Issue 56 item 5: a step whose pair forces fold an element is undone and retried with the pairs
    // softened by half (up to max_backoffs times in a plateau); the softening is relaxed by half at
    // each later plateau, so the annealing goes on instead of ending at the first inversion.
    double softening = 1.0;
    constexpr int max_backoffs = 6;
    std::map<std::int32_t, double> applied;
    for (int plateau = 0; plateau < plateaus && result.stopped.empty(); ++plateau) {
        const auto plateau_start = std::chrono::steady_clock::now();
        PlateauReport report;
        report.plateau = plateau;
        softening = std::min(1.0, 2.0 * softening);
        int backoffs = 0;
        for (const auto& [label, s] : options.schedules) report.stiffness_n[label] = s.stiffness(plateau);
        const int factorisations_before = integrator.total_factorisations();
        if (options.newton_iterations_per_step > 0) integrator.refresh_tangent();
        for (int step = 0; step < options.max_steps_per_plateau; ++step) {
            const auto& u = integrator.displacement_mm();
            for (std::size_t i = 0; i < n; ++i) x[i] = rest[i] + u[i];
            const auto match_start = std::chrono::steady_clock::now();
            pairs = matcher.match(x, cloud, options.matching, &report.matching);
            result.matching_s += seconds_since(match_start);
            if (pairs.empty())
                fail("surface registration: no pair left after pruning at plateau {}: {} of {} cloud points lie farther than {} mm from the model's "
                     "surface (is the cloud in the model's space, mm, LPS?)",
                     plateau, report.matching.pruned_far, report.matching.points, options.matching.max_distance_mm);
            std::fill(forces.begin(), forces.end(), 0.0);
            std::fill(stiffness.begin(), stiffness.end(), 0.0);
            for (const auto& [label, k] : report.stiffness_n) applied[label] = softening * k;
            accumulate_pair_forces(pairs, matcher.source(), applied, options.force, forces, &stiffness);
            if (!options.load_nodes.empty())
                for (std::size_t i = 0; i < n; ++i)
                    if (!may_load[i / 3]) forces[i] = stiffness[i] = 0.0;
            const bool elastic_support = options.support_stiffness_n_per_mm > 0;
            if (elastic_support) elastic_supports.add_restoring(u, forces, stiffness);
            Loads loads;
            loads.external_forces_n = forces;
            if (!options.fixed_nodes.empty() && !elastic_support)
                loads.constraints.push_back({"support", options.fixed_nodes, {true, true, true}, Vec3::Zero()});
            for (const auto& partial : options.partial_supports) loads.constraints.push_back(partial);
            integrator.set_loads(std::move(loads));
            integrator.set_external_stiffness(stiffness);
            previous = u;
            BackwardEulerStep s;
            std::string failure;
            try {
                s = integrator.step();
            } catch (const Error& e) {
                failure = e.what(); // a step that cannot be solved under these forces: backed off like an inversion
            }
            if (!failure.empty() || s.inverted_elements > 0) {
                if (backoffs < max_backoffs) {
                    integrator.set_state(previous, std::vector<double>(n, 0.0));
                    integrator.refresh_tangent();
                    softening *= 0.5;
                    ++backoffs;
                    ++result.backoffs;
                    logger()->debug("surface registration: plateau {}: {}; the step is retried with the pairs softened to {:.3g} of their stiffness",
                                    plateau + 1, failure.empty() ? fmt::format("{} element(s) inverted", s.inverted_elements) : failure, softening);
                    continue;
                }
                result.inverted_elements = s.inverted_elements;
                result.stopped = fmt::format("{} at plateau {} of {} (stiffness {:.3g} N, step {}) even with the pairs softened to {:.3g} of their "
                                             "stiffness: the annealing stopped and the result of {} is kept (lower the traction ratio or raise d90 "
                                             "to go further)",
                                             failure.empty() ? fmt::format("{} element(s) of the model inverted", s.inverted_elements) : failure,
                                             plateau + 1, plateaus, report.stiffness_n.begin()->second, report.steps + 1, softening,
                                             plateau == 0 ? std::string("the rest state") : fmt::format("plateau {}", plateau));
                logger()->warn("surface registration: {}", result.stopped);
                break;
            }
            ++report.steps;
            ++result.steps;
            result.newton_iterations += s.newton_iterations;
            result.force_s += s.force_s;
            result.assembly_s += s.assembly_s;
            result.factorisation_s += s.factorisation_s;
            result.solve_s += s.solve_s;
            double largest = 0.0, squares = 0.0;
            const auto& u1 = integrator.displacement_mm();
            for (std::size_t i = 0; i < n; i += 3) {
                const double motion = std::hypot(u1[i] - previous[i], u1[i + 1] - previous[i + 1], u1[i + 2] - previous[i + 2]);
                largest = std::max(largest, motion);
                squares += motion * motion;
            }
            report.last_step_mm = largest;
            report.last_step_rms_mm = std::sqrt(squares / static_cast<double>(n / 3));
            if (largest <= options.plateau_tolerance_mm || report.last_step_rms_mm <= options.plateau_rms_fraction * options.plateau_tolerance_mm) {
                report.reached = true;
                break;
            }
        }
        report.factorisations = integrator.total_factorisations() - factorisations_before;
        report.seconds = seconds_since(plateau_start);
        logger()->debug("surface registration: plateau {}/{}: {} steps{}, {} pairs (pruned {} by distance, {} by normal), mean distance {:.3f} mm, "
                        "last step {:.4f} mm (rms {:.5f}), {:.2f} s",
                        plateau + 1, plateaus, report.steps, report.reached ? "" : " (not settled)", report.matching.kept,
                        report.matching.pruned_distance, report.matching.pruned_normal, report.matching.mean_distance_mm, report.last_step_mm,
                        report.last_step_rms_mm, report.seconds);
        result.plateaus.push_back(report);
        if (result.stopped.empty()) last_good = integrator.displacement_mm();
        if (progress)
            progress(static_cast<double>(plateau + 1) / plateaus,
                     fmt::format("plateau {}/{}, mean pair distance {:.2f} mm", plateau + 1, plateaus, report.matching.mean_distance_mm));
    }
    result.displacement_mm = result.stopped.empty() ? integrator.displacement_mm() : last_good;
    for (std::size_t i = 0; i < n; ++i) x[i] = rest[i] + result.displacement_mm[i];
    pairs = matcher.match(x, cloud, options.matching);
    mark_used(pairs, matcher.source(), result.node_used);
    result.factorisations = integrator.total_factorisations();
    result.final_softening = softening;
    result.seconds = seconds_since(start);
    return result;
}

RigidSurfaceResult register_surface_rigid(const std::vector<double>& rest, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                          const MatchingOptions& matching, bool use_labels, const RigidIcpSettings& settings)
{
    const auto start = std::chrono::steady_clock::now();
    const int max_iterations = settings.max_iterations;
    const double tolerance_mm = settings.tolerance_mm;
    if (max_iterations < 1) fail("rigid surface registration: max iterations {} must be ≥ 1", max_iterations);
    if (!(settings.anchor_weight >= 0 && std::isfinite(settings.anchor_weight)))
        fail("rigid surface registration: anchor weight {} must be ≥ 0", settings.anchor_weight);
    const std::size_t n = rest.size();
    for (const auto a : settings.anchors)
        if (a < 0 || 3 * static_cast<std::size_t>(a) >= n) fail("rigid surface registration: anchor node {} is not a model node", a);
    RigidSurfaceResult result;
    result.node_used.assign(n / 3, 0);
    std::vector<double> x(n), next(n);
    std::vector<SurfacePair> pairs;
    const auto& triangles = matcher.source().triangles;
    Mat3 rotation = settings.initial_rotation;
    Vec3 translation = settings.initial_translation;
    for (std::size_t i = 0; i < n; i += 3) {
        const Vec3 y = rotation * Vec3(rest[i], rest[i + 1], rest[i + 2]) + translation;
        for (int d = 0; d < 3; ++d) x[i + d] = y[d];
    }
    for (int iteration = 0; iteration < max_iterations; ++iteration) {
        pairs = use_labels ? matcher.match(x, cloud, matching, &result.matching) : match_unlabelled(x, matcher.source(), cloud, matching, &result.matching);
        if (pairs.size() < 3)
            fail("rigid surface registration: {} pair(s) after pruning ({} of {} cloud points farther than {} mm from the model's surface); at "
                 "least 3 are needed",
                 pairs.size(), result.matching.pruned_far, result.matching.points, matching.max_distance_mm);
        // Point-to-plane ICP (Chen & Medioni; plain point-to-point ICP crawls along sliding
        // directions): the small motion (ω, τ) minimising Σ ((ω × s + τ + s − q)·n)² over the pairs,
        // n the source triangle's current normal, plus 1e-3 × the point-to-point terms, which only
        // matter where the surface leaves a motion undetermined (a plane, a cylinder).
        Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
        Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
        const double point_weight = 1e-3;
        for (const auto& p : pairs) {
            const auto& tri = triangles[static_cast<std::size_t>(p.triangle)];
            const Vec3 x0(x[3 * tri[0]], x[3 * tri[0] + 1], x[3 * tri[0] + 2]), x1(x[3 * tri[1]], x[3 * tri[1] + 1], x[3 * tri[1] + 2]),
                x2(x[3 * tri[2]], x[3 * tri[2] + 1], x[3 * tri[2] + 2]);
            Vec3 normal = (x1 - x0).cross(x2 - x0);
            if (normal.norm() > 0) normal.normalize();
            const Vec3 s = p.source, gap = p.target - p.source;
            Eigen::Matrix<double, 6, 1> row;
            row << s.cross(normal), normal;
            a += row * row.transpose();
            b += row * gap.dot(normal);
            for (int d = 0; d < 3; ++d) {
                const Vec3 e = Vec3::Unit(d);
                row << s.cross(e), e;
                a += point_weight * row * row.transpose();
                b += point_weight * row * gap[d];
            }
        }
        // Supports as anchors: each pulled back to its rest position (point-to-point).
        if (!settings.anchors.empty() && settings.anchor_weight > 0) {
            const double w = settings.anchor_weight * static_cast<double>(pairs.size()) / static_cast<double>(settings.anchors.size());
            for (const auto node : settings.anchors) {
                const auto q = 3 * static_cast<std::size_t>(node);
                const Vec3 s(x[q], x[q + 1], x[q + 2]), gap = Vec3(rest[q], rest[q + 1], rest[q + 2]) - s;
                for (int d = 0; d < 3; ++d) {
                    const Vec3 e = Vec3::Unit(d);
                    Eigen::Matrix<double, 6, 1> row;
                    row << s.cross(e), e;
                    a += w * row * row.transpose();
                    b += w * row * gap[d];
                }
            }
        }
        const Eigen::Matrix<double, 6, 1> motion = a.ldlt().solve(b);
        const Vec3 omega = motion.head<3>();
        const Mat3 step = omega.norm() > 0 ? Mat3(Eigen::AngleAxisd(omega.norm(), omega.normalized())) : Mat3::Identity();
        // x ↦ step (x) + τ about the origin of the linearisation: compose with the transform so far.
        rotation = step * rotation;
        translation = step * translation + Vec3(motion.tail<3>());
        double largest = 0.0;
        for (std::size_t i = 0; i < n; i += 3) {
            const Vec3 y = rotation * Vec3(rest[i], rest[i + 1], rest[i + 2]) + translation;
            largest = std::max(largest, (y - Vec3(x[i], x[i + 1], x[i + 2])).norm());
            for (int d = 0; d < 3; ++d) next[i + d] = y[d];
        }
        x.swap(next);
        result.iterations = iteration + 1;
        if (largest <= tolerance_mm) {
            result.converged = true;
            break;
        }
    }
    result.rotation = rotation;
    result.translation = translation;
    result.displacement_mm.resize(n);
    for (std::size_t i = 0; i < n; ++i) result.displacement_mm[i] = x[i] - rest[i];
    mark_used(pairs, matcher.source(), result.node_used);
    result.seconds = seconds_since(start);
    return result;
}

RigidMotion implied_rigid_motion(const std::vector<double>& rest, const std::vector<double>& u)
{
    if (rest.size() != u.size() || rest.size() % 3 != 0 || rest.empty())
        fail("implied rigid motion: {} rest coordinates and {} displacement components", rest.size(), u.size());
    const auto nodes = static_cast<Eigen::Index>(rest.size() / 3);
    Eigen::Matrix3Xd from(3, nodes), to(3, nodes);
    for (Eigen::Index i = 0; i < nodes; ++i)
        for (int d = 0; d < 3; ++d) {
            from(d, i) = rest[static_cast<std::size_t>(3 * i + d)];
            to(d, i) = from(d, i) + u[static_cast<std::size_t>(3 * i + d)];
        }
    const Eigen::Matrix4d t = Eigen::umeyama(from, to, false);
    RigidMotion m;
    m.rotation = t.topLeftCorner<3, 3>();
    m.translation = t.topRightCorner<3, 1>();
    m.angle_deg = Eigen::AngleAxisd(m.rotation).angle() * 180.0 / M_PI;
    const Eigen::Matrix3Xd rest_of = to - ((m.rotation * from).colwise() + m.translation);
    m.residual_rms_mm = std::sqrt(rest_of.colwise().squaredNorm().mean());
    return m;
}

namespace {
SurfaceMesh posed_surface(const std::vector<double>& rest, const LabelledTriangles& source, const Mat3& r, const Vec3& t)
{
    SurfaceMesh s;
    s.vertices.reserve(rest.size() / 3);
    for (std::size_t i = 0; i < rest.size(); i += 3) s.vertices.push_back(r * Vec3(rest[i], rest[i + 1], rest[i + 2]) + t);
    s.triangles = source.triangles;
    return s;
}
double rotation_between_deg(const Mat3& a, const Mat3& b) { return Eigen::AngleAxisd(a.transpose() * b).angle() * 180.0 / M_PI; }
} // namespace

RobustRigidResult register_surface_rigid_robust(const std::vector<double>& rest, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud,
                                                const MatchingOptions& matching, bool use_labels, const RobustRigidOptions& options)
{
    if (!(options.support_tolerance_mm > 0) || !(options.improvement >= 0) || !(options.start_angle_deg > 0) || !(options.anchor_weight > 0))
        fail("robust rigid registration: support tolerance {} mm, improvement {}, start angle {}° and anchor weight {} must be > 0",
             options.support_tolerance_mm, options.improvement, options.start_angle_deg, options.anchor_weight);
    // Starts: identity; principal axes (cloud onto the model's surface nodes, four sign choices);
    // ± the start angle about x, y and z (about the model's centre).
    std::vector<std::pair<std::string, Mat3>> rotations{{"identity", Mat3::Identity()}};
    std::vector<Vec3> surface_points;
    {
        std::vector<std::uint8_t> on(rest.size() / 3, 0);
        for (const auto& tri : matcher.source().triangles)
            for (const auto node : tri) on[static_cast<std::size_t>(node)] = 1;
        for (std::size_t i = 0; i < on.size(); ++i)
            if (on[i]) surface_points.emplace_back(rest[3 * i], rest[3 * i + 1], rest[3 * i + 2]);
    }
    const detail::PrincipalFrame model_frame = detail::principal_frame(surface_points), cloud_frame = detail::principal_frame(cloud.points);
    const Vec3 centre = model_frame.centre;
    for (int signs = 0; signs < 4; ++signs)
        rotations.push_back({fmt::format("principal axes {}", signs), cloud_frame.axes * detail::axis_flip(signs) * model_frame.axes.transpose()});
    const double angle = options.start_angle_deg * M_PI / 180.0;
    for (int axis = 0; axis < 3; ++axis)
        for (const double sign : {1.0, -1.0})
            rotations.push_back({fmt::format("{:+.0f}° about {}", sign * options.start_angle_deg, "xyz"[axis]),
                                 Mat3(Eigen::AngleAxisd(sign * angle, Vec3::Unit(axis)))});

    RobustRigidResult out;
    // The starts are independent fits: run side by side (issue 56's time: 11 starts were 2.7 s of an
    // 11.7 s registration of the public liver), each serial inside, gathered in start order so the
    // answer does not depend on the team. Errors are kept per start and judged afterwards in order.
    const int count = static_cast<int>(rotations.size());
    std::vector<std::optional<RigidCandidate>> slots(rotations.size());
    std::vector<std::exception_ptr> errors(rotations.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < count; ++k) {
        try {
            const auto& [name, r0] = rotations[static_cast<std::size_t>(k)];
            RigidIcpSettings settings;
            settings.initial_rotation = r0;
            if (name != "identity") settings.max_iterations = 100, settings.tolerance_mm = 1e-3; // alternatives: to 1 µm, not 0.1 µm
            // Principal-axes starts move the model's centre onto the cloud's; the others turn about it.
            settings.initial_translation = name.rfind("principal", 0) == 0 ? Vec3(cloud_frame.centre - r0 * centre) : Vec3(centre - r0 * centre);
            RigidCandidate c;
            c.start = name;
            c.result = register_surface_rigid(rest, matcher, cloud, matching, use_labels, settings);
            c.cloud_mean_mm = points_to_surface(cloud.points, posed_surface(rest, matcher.source(), c.result.rotation, c.result.translation),
                                                "cloud to posed model").mean_mm;
            for (const auto node : options.supports) {
                const auto q = 3 * static_cast<std::size_t>(node);
                c.support_motion_mm = std::max(c.support_motion_mm, Vec3(c.result.displacement_mm[q], c.result.displacement_mm[q + 1],
                                                                         c.result.displacement_mm[q + 2]).norm());
            }
            c.plausible = c.support_motion_mm <= options.support_tolerance_mm;
            slots[static_cast<std::size_t>(k)] = std::move(c);
        } catch (...) {
            errors[static_cast<std::size_t>(k)] = std::current_exception();
        }
    }
    for (std::size_t k = 0; k < rotations.size(); ++k) {
        if (errors[k]) {
            const std::string& name = rotations[k].first;
            try {
                std::rethrow_exception(errors[k]);
            } catch (const Interrupted&) {
                throw;
            } catch (const Error& e) {
                // The plain fit failing where the cloud meets no part of the model at rest is the
                // caller's error (a cloud in another space); a start that drifts off the cloud on the
                // way (neohookean/s4 frame 0 of the adjoint-liver) is only a start that failed.
                if (name == "identity") {
                    std::vector<double> at_rest = rest;
                    if (matcher.match(at_rest, cloud, matching).size() < 3) throw;
                }
                logger()->debug("robust rigid: start {} failed: {}", name, e.what());
                continue;
            }
        }
        if (slots[k]) out.candidates.push_back(std::move(*slots[k]));
    }
    if (out.candidates.empty()) fail("robust rigid: every one of the {} starts lost the cloud", rotations.size());
    const RigidCandidate* identity = out.candidates.front().start == "identity" ? &out.candidates.front() : nullptr;
    const RigidCandidate* best = nullptr;
    for (const auto& c : out.candidates)
        if (c.plausible && (!best || c.cloud_mean_mm < best->cloud_mean_mm)) best = &c;
    // Another start must beat the plain fit clearly: a small gain does not pay for a new pose.
    if (best && identity && identity->plausible && best->cloud_mean_mm >= (1.0 - options.improvement) * identity->cloud_mean_mm) best = identity;
    if (best) {
        out.chosen = best->result;
        out.chosen_start = best->start;
        out.decision = best == identity ? "the plain fit (identity start): no other start fitted the cloud clearly better while keeping the supports"
                       : identity   ? fmt::format("start '{}': fits the cloud {:.0f} % closer than the plain fit and keeps the supports",
                                                  best->start, 100.0 * (1.0 - best->cloud_mean_mm / identity->cloud_mean_mm))
                                    : fmt::format("start '{}': the best fit that keeps the supports (the plain fit from the identity drifted off the cloud)",
                                                  best->start);
        // Ambiguity: another plausible pose, as good within the margin, rotated far from this one.
        for (const auto& c : out.candidates)
            if (c.plausible && &c != best && c.cloud_mean_mm <= (1.0 + options.ambiguous_fit) * best->cloud_mean_mm &&
                rotation_between_deg(c.result.rotation, best->result.rotation) > options.ambiguous_angle_deg)
                out.pose_determined = false;
    } else {
        RigidIcpSettings anchored;
        anchored.anchors = options.supports;
        anchored.anchor_weight = options.anchor_weight;
        out.chosen = register_surface_rigid(rest, matcher, cloud, matching, use_labels, anchored);
        out.chosen_start = "anchored to the supports";
        out.decision = fmt::format("no start kept every support node within {:.0f} mm: the fit was redone with the supports as anchors",
                                   options.support_tolerance_mm);
    }
    return out;
}

SurfaceRegistrationResult register_cloud(const Model& model, const LabelledPointCloud& cloud, const CloudRegistrationSettings& settings,
                                         const std::function<void(double, const std::string&)>& progress)
{
    model.validate("surface registration: the model");
    if (model.surface.triangles.empty()) fail("surface registration: the model has no surface to match the cloud to");
    if (cloud.points.empty()) fail("surface registration: the cloud has no point");
    if (!(settings.traction_ratio > 0.0) || !std::isfinite(settings.traction_ratio))
        fail("surface registration: traction ratio {} must be > 0", settings.traction_ratio);
    if (!(settings.young_modulus_pa >= 0.0) || !std::isfinite(settings.young_modulus_pa))
        fail("surface registration: Young's modulus {} Pa of the pair stiffness must be > 0 (0: the surface's softest tissue)", settings.young_modulus_pa);
    TledOptions tled;
    tled.law = MaterialLaw::corotational; // paper 001's law, whatever law the model was built for
    const TledModel tled_model(model.mesh, model.tissues, tled);
    const SurfaceMatcher matcher(model.surface, model.mesh.node_count(), "the model's surface");
    SurfaceRegistrationOptions options = settings.options;
    options.fixed_nodes = model.held_nodes();
    options.partial_supports = model.partial_supports();
    options.structures = model.structure_pointers();
    options.coupling = model.coupling.get();
    std::set<std::int32_t> surface_nodes;
    for (const auto& t : model.surface.triangles) surface_nodes.insert(t.begin(), t.end());
    std::size_t held_on_surface = 0;
    for (auto n : options.fixed_nodes) held_on_surface += surface_nodes.count(n);
    if (!options.fixed_nodes.empty() && held_on_surface >= surface_nodes.size())
        fail("surface registration: the supports take every one of the {} surface nodes; nothing is left free to meet the cloud", surface_nodes.size());
    const double young = settings.young_modulus_pa > 0.0 ? settings.young_modulus_pa : model.surface_young_modulus_pa();
    options.schedules = paper001_schedules(pair_stiffness_n(settings.traction_ratio, young, mean_point_spacing_mm(cloud.points)));
    return register_surface_biomechanical(tled_model, matcher, cloud, options, progress);
}

SurfaceRegistrationResult register_surface_cloud(const VolumeMesh& mesh, const LabelledTriangles& surface, const LabelledPointCloud& cloud,
                                                 const SurfaceCloudProblem& problem, const std::function<void(double, const std::string&)>& progress)
{
    if (mesh.cell_type != CellType::tetrahedron) fail("surface registration: the model must hold tetrahedra (paper 001's model)");
    for (auto n : problem.support_nodes)
        if (n < 0 || static_cast<std::size_t>(n) >= mesh.node_count()) fail("surface registration: support node {} is not a node of the model ({} nodes)", n, mesh.node_count());
    std::vector<std::int32_t> held = problem.support_nodes;
    if (problem.posterior_support) {
        const auto nodes = surface_nodes_facing(mesh, surface, Vec3::UnitY(), 0.5);
        if (nodes.empty()) fail("surface registration: no surface node faces posterior (+y) in the model");
        held.insert(held.end(), nodes.begin(), nodes.end());
    }
    Model model;
    model.mesh = mesh;
    model.tissues = homogeneous_liver_tissues(problem.young_modulus_pa, problem.poisson_ratio);
    model.law = MaterialLaw::corotational;
    model.surface = surface;
    if (!held.empty()) model.supports.push_back({"support", held, {true, true, true}, Vec3::Zero()});
    CloudRegistrationSettings settings;
    settings.traction_ratio = problem.traction_ratio;
    settings.young_modulus_pa = problem.young_modulus_pa;
    settings.options = problem.options;
    return register_cloud(model, cloud, settings, progress);
}

} // namespace physreg
