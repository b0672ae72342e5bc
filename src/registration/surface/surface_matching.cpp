// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/surface/surface_matching.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace physreg {

void MatchingOptions::validate() const
{
    if (!(distance_fraction > 0 && distance_fraction <= 1)) fail("matching: distance fraction d_t = {} must be in (0, 1]", distance_fraction);
    if (!(normal_agreement >= -1 && normal_agreement <= 1)) fail("matching: normal agreement n_t = {} must be in [-1, 1]", normal_agreement);
    if (!(max_distance_mm > 0)) fail("matching: the largest pair distance {} mm must be > 0", max_distance_mm);
}

namespace {

std::vector<Vec3> as_points(const std::vector<double>& positions)
{
    std::vector<Vec3> points(positions.size() / 3);
    for (std::size_t i = 0; i < points.size(); ++i) points[i] = Vec3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
    return points;
}

Vec3 triangle_normal(const std::vector<Vec3>& x, const std::array<std::int32_t, 3>& t)
{
    const Vec3 n = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);
    const double length = n.norm();
    return length > 0 ? Vec3(n / length) : Vec3::Zero();
}

void check_cloud(const LabelledPointCloud& cloud)
{
    if (cloud.points.empty()) fail("matching: the point cloud is empty");
    if (cloud.labels.size() != cloud.points.size())
        fail("matching: the point cloud has {} points but {} labels", cloud.points.size(), cloud.labels.size());
    if (!cloud.normals.empty() && cloud.normals.size() != cloud.points.size())
        fail("matching: the point cloud has {} points but {} normals", cloud.points.size(), cloud.normals.size());
    for (std::size_t i = 0; i < cloud.points.size(); ++i)
        if (!cloud.points[i].allFinite()) fail("matching: cloud point {} has a non-finite coordinate", i);
}

/// Distance pruning per label, then the normal test; fills the statistics.
std::vector<SurfacePair> prune(std::vector<SurfacePair> pairs, const std::vector<Vec3>& x, const LabelledTriangles& source,
                               const LabelledPointCloud& cloud, const MatchingOptions& options, MatchStatistics* statistics)
{
    MatchStatistics s;
    s.points = cloud.points.size();
    const std::size_t before = pairs.size();
    std::erase_if(pairs, [&](const SurfacePair& p) { return !(p.distance_mm() <= options.max_distance_mm); });
    s.pruned_far = before - pairs.size();
    std::map<std::int32_t, double> largest;
    for (const auto& p : pairs) largest[p.label] = std::max(largest[p.label], p.distance_mm());
    std::vector<SurfacePair> kept;
    kept.reserve(pairs.size());
    for (const auto& p : pairs) {
        const double d = p.distance_mm();
        if (d > options.distance_fraction * largest[p.label]) {
            ++s.pruned_distance;
            continue;
        }
        if (options.use_normals && !cloud.normals.empty()) {
            const Vec3& nt = cloud.normals[static_cast<std::size_t>(p.point)];
            const double length = nt.norm();
            if (length > 0 && nt.dot(triangle_normal(x, source.triangles[static_cast<std::size_t>(p.triangle)])) / length < options.normal_agreement) {
                ++s.pruned_normal;
                continue;
            }
        }
        kept.push_back(p);
        s.mean_distance_mm += d;
        s.max_distance_mm = std::max(s.max_distance_mm, d);
    }
    s.kept = kept.size();
    if (s.kept > 0) s.mean_distance_mm /= static_cast<double>(s.kept);
    if (statistics) *statistics = s;
    return kept;
}

SurfacePair make_pair(std::int32_t point, const ClosestTriangle& hit, const LabelledPointCloud& cloud, std::int32_t label)
{
    SurfacePair p;
    p.point = point;
    p.triangle = hit.triangle;
    p.weights = hit.weights;
    p.source = hit.point;
    p.target = cloud.points[static_cast<std::size_t>(point)];
    p.label = label;
    return p;
}

} // namespace

SurfaceMatcher::SurfaceMatcher(LabelledTriangles source, std::size_t node_count, const std::string& what)
    : m_source(std::move(source)), m_node_count(node_count)
{
    m_source.validate(node_count, what);
    for (std::size_t t = 0; t < m_source.triangles.size(); ++t) m_by_label[m_source.labels[t]].push_back(static_cast<std::int32_t>(t));
}

std::vector<std::int32_t> SurfaceMatcher::labels() const
{
    std::vector<std::int32_t> out;
    for (const auto& [label, triangles] : m_by_label) out.push_back(label);
    return out;
}

std::vector<SurfacePair> SurfaceMatcher::match(const std::vector<double>& positions, const LabelledPointCloud& cloud, const MatchingOptions& options,
                                               MatchStatistics* statistics) const
{
    options.validate();
    check_cloud(cloud);
    if (positions.size() != 3 * m_node_count) fail("matching: {} coordinates for {} model nodes", positions.size(), m_node_count);
    const std::vector<Vec3> x = as_points(positions);
    std::map<std::int32_t, std::vector<std::int32_t>> points_by_label;
    for (std::size_t i = 0; i < cloud.points.size(); ++i) points_by_label[cloud.labels[i]].push_back(static_cast<std::int32_t>(i));
    std::vector<SurfacePair> pairs;
    pairs.reserve(cloud.points.size());
    for (const auto& [label, points] : points_by_label) {
        const auto found = m_by_label.find(label);
        if (found == m_by_label.end())
            fail("matching: {} cloud point(s) carry label {} but the model's surface has no region with that label", points.size(), label);
        const TriangleSearch search(x, m_source.triangles, found->second);
        if (search.empty()) fail("matching: the model's region with label {} has only degenerate triangles", label);
        for (auto i : points) pairs.push_back(make_pair(i, search.closest(cloud.points[static_cast<std::size_t>(i)]), cloud, label));
    }
    return prune(std::move(pairs), x, m_source, cloud, options, statistics);
}

std::vector<SurfacePair> match_unlabelled(const std::vector<double>& positions, const LabelledTriangles& source, const LabelledPointCloud& cloud,
                                          const MatchingOptions& options, MatchStatistics* statistics)
{
    options.validate();
    check_cloud(cloud);
    const std::vector<Vec3> x = as_points(positions);
    source.validate(x.size(), "matching source");
    const TriangleSearch search(x, source.triangles);
    if (search.empty()) fail("matching: the model's surface has only degenerate triangles");
    std::vector<SurfacePair> pairs;
    pairs.reserve(cloud.points.size());
    for (std::size_t i = 0; i < cloud.points.size(); ++i) pairs.push_back(make_pair(static_cast<std::int32_t>(i), search.closest(cloud.points[i]), cloud, 0));
    return prune(std::move(pairs), x, source, cloud, options, statistics);
}

double ArctanForceLaw::sigma_per_mm() const { return std::tan(0.9 * std::numbers::pi / 2) / d90_mm; }

double ArctanForceLaw::magnitude(double k, double d) const { return k * (2 / std::numbers::pi) * std::atan(sigma_per_mm() * d); }

double ArctanForceLaw::potential(double k, double d) const
{
    const double sigma = sigma_per_mm();
    return k * (2 / std::numbers::pi) * (d * std::atan(sigma * d) - std::log1p(sigma * sigma * d * d) / (2 * sigma));
}

double ArctanForceLaw::radial_stiffness(double k, double d) const
{
    const double sigma = sigma_per_mm();
    return k * (2 / std::numbers::pi) * sigma / (1 + sigma * sigma * d * d);
}

double ArctanForceLaw::stiffness_bound(double k, double d) const
{
    const double sigma = sigma_per_mm();
    const double x = sigma * d;
    return k * (2 / std::numbers::pi) * sigma * (x > 1e-8 ? std::atan(x) / x : 1.0);
}

void ArctanForceLaw::validate() const
{
    if (!(d90_mm > 0 && std::isfinite(d90_mm))) fail("force law: d90 = {} mm must be > 0", d90_mm);
}

double AnnealingSchedule::stiffness(int n) const
{
    if (n >= ramp_plateaus) return k_max_n;
    const double ratio = static_cast<double>(std::max(n, 0)) / ramp_plateaus;
    return k_min_n + std::pow(ratio, exponent) * (k_max_n - k_min_n);
}

void AnnealingSchedule::validate(const std::string& what) const
{
    if (!(k_min_n >= 0 && std::isfinite(k_min_n))) fail("{}: k_min = {} N must be ≥ 0", what, k_min_n);
    if (!(k_max_n > 0 && std::isfinite(k_max_n))) fail("{}: k_max = {} N must be > 0", what, k_max_n);
    if (k_min_n > k_max_n) fail("{}: k_min = {} N exceeds k_max = {} N", what, k_min_n, k_max_n);
    if (ramp_plateaus < 1) fail("{}: r = {} must be ≥ 1", what, ramp_plateaus);
    if (!(exponent > 0 && std::isfinite(exponent))) fail("{}: exponent e = {} must be > 0", what, exponent);
}

int plateau_count(const std::map<std::int32_t, AnnealingSchedule>& schedules)
{
    int r = 0;
    for (const auto& [label, s] : schedules) r = std::max(r, s.ramp_plateaus);
    return r + 1;
}

void accumulate_pair_forces(const std::vector<SurfacePair>& pairs, const LabelledTriangles& source, const std::map<std::int32_t, double>& stiffness_n,
                            const ArctanForceLaw& law, std::vector<double>& forces, std::vector<double>* stiffness)
{
    for (const auto& p : pairs) {
        const auto k = stiffness_n.find(p.label);
        if (k == stiffness_n.end()) fail("pair forces: no stiffness for label {}", p.label);
        const Vec3 gap = p.target - p.source;
        const double d = gap.norm();
        const auto& tri = source.triangles[static_cast<std::size_t>(p.triangle)];
        const Vec3 f = d > 0 ? Vec3(law.magnitude(k->second, d) / d * gap) : Vec3::Zero();
        const double kb = stiffness ? law.stiffness_bound(k->second, d) : 0.0;
        for (int c = 0; c < 3; ++c) {
            const auto node = static_cast<std::size_t>(tri[c]);
            for (int i = 0; i < 3; ++i) {
                forces[3 * node + i] += p.weights[c] * f[i];
                if (stiffness) (*stiffness)[3 * node + i] += p.weights[c] * kb;
            }
        }
    }
}

double mean_point_spacing_mm(const std::vector<Vec3>& points)
{
    if (points.size() < 2) return 0.0;
    double sum = 0.0;
    for (std::size_t i = 0; i < points.size(); ++i) {
        double best = std::numeric_limits<double>::infinity();
        for (std::size_t j = 0; j < points.size(); ++j)
            if (j != i) best = std::min(best, (points[i] - points[j]).squaredNorm());
        sum += std::sqrt(best);
    }
    return sum / static_cast<double>(points.size());
}

} // namespace physreg
