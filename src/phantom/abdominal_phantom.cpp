// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/phantom/abdominal_phantom.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace physreg {
namespace {

struct Ellipsoid {
    Vec3 centre, radii;
    double value(const Vec3& p) const { return (p - centre).cwiseQuotient(radii).squaredNorm(); }
};

struct Tube {
    Vec3 a, b;
    double ra, rb; // radius at a and at b, mm
    double distance_minus_radius(const Vec3& p) const
    {
        const Vec3 ab = b - a;
        const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        return (p - (a + t * ab)).norm() - (ra + t * (rb - ra));
    }
};

// Liver frame → body frame.
const Vec3 liver_offset(-30.0, -5.0, 0.0);

// Vessel tree in the liver frame: a portal-like trunk from the hilum, two main branches, each
// splitting again; radii decrease along every path.
std::vector<Tube> vessel_tubes()
{
    const Vec3 hilum(-10, 25, -25), right_fork(-50, 12, -8), left_fork(35, 0, -5), right_mid(-72, 6, 2);
    return {{hilum, right_fork, 4.5, 3.5},          {right_fork, {-85, 0, 12}, 3.2, 1.8}, {right_fork, {-50, -30, 10}, 2.8, 1.6},
            {hilum, left_fork, 4.0, 3.0},           {left_fork, {78, -18, 8}, 2.8, 1.5},  {left_fork, {40, -38, 16}, 2.2, 1.4},
            {right_mid, {-70, 35, -10}, 1.8, 1.2}};
}

// Three lobes, smooth union (soft minimum of the ellipsoid functions), minus the umbilical cleft.
bool inside_liver(const Vec3& p_body)
{
    // Like the real phantom's liver (≈ 23 % of its bounding box), the lobes are slim: a right lobe, its
    // thinner anterior extension, the left lobe and a posterior (caudate-like) part.
    static const Ellipsoid lobes[] = {{{-45, 5, 0}, {45, 38, 44}},   // right lobe
                                      {{-30, -35, -5}, {40, 30, 16}}, // anterior extension of the right lobe
                                      {{40, -15, 8}, {52, 24, 16}},   // left lobe
                                      {{-5, 35, -12}, {26, 34, 18}}}; // caudate / posterior part
    static const Ellipsoid cleft{{58, -28, -2}, {6, 22, 22}};         // umbilical-notch-like cleft
    const Vec3 p = p_body - liver_offset;
    double sum = 0.0;
    for (const auto& e : lobes) sum += std::exp(-6.0 * (e.value(p) - 1.0));
    return sum > 1.0 && cleft.value(p) > 1.0;
}

} // namespace

LabelVolume make_cirs057a_phantom(double voxel_mm)
{
    if (!(voxel_mm >= 0.5 && voxel_mm <= 6.0)) fail("phantom: voxel size {} mm outside 0.5 … 6 mm", voxel_mm);
    const auto tubes = vessel_tubes();
    const Ellipsoid lesions[] = {{{-60, 22, 10}, Vec3(7.2, 6.8, 7.0)}, {{-30, -33, -3}, Vec3(7.0, 7.0, 7.0)},
                                 {{48, -24, 6}, Vec3(4.5, 4.5, 4.5)},  {{-70, -10, -12}, Vec3(4.0, 4.0, 4.0)},
                                 {{-20, 10, 18}, Vec3(2.5, 2.5, 2.5)}, {{20, -20, 2}, Vec3(2.5, 2.5, 2.5)}};
    const Ellipsoid kidneys[] = {{{-78, 62, -38}, {22, 17, 28}}, {{72, 60, -30}, {22, 17, 30}}};

    LabelVolume volume;
    ImageGeometry& g = volume.geometry;
    const Vec3 lower(-145, -110, -70), upper(145, 95, 70); // mm: body plus a margin of air
    for (int a = 0; a < 3; ++a) g.size[a] = static_cast<std::int64_t>(std::ceil((upper[a] - lower[a]) / voxel_mm));
    g.spacing = Vec3::Constant(voxel_mm);
    g.origin = lower + Vec3::Constant(0.5 * voxel_mm);
    volume.labels.assign(static_cast<std::size_t>(g.voxel_count()), 0);
#pragma omp parallel for schedule(static)
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const Vec3 p = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                // Body: superellipse cross-section 270 × 200 mm, flat base at y = 85 mm, 130 mm long.
                const double section = std::pow(std::abs(p.x()) / 135.0, 2.5) + std::pow(std::abs(p.y()) / 100.0, 2.5);
                if (section > 1.0 || p.y() > 85.0 || std::abs(p.z()) > 65.0) continue;
                std::uint16_t label = phantom_label::body;
                const Vec3 q = p - liver_offset;
                if (inside_liver(p)) {
                    label = phantom_label::liver;
                    for (const auto& t : tubes)
                        if (t.distance_minus_radius(q) <= 0) label = phantom_label::vessel;
                    for (const auto& l : lesions)
                        if (l.value(q) <= 1.0) label = phantom_label::lesion;
                } else {
                    // Spine: vertebral body and a posterior process, along z.
                    const double vertebra = std::hypot(p.x() / 20.0, (p.y() - 62.0) / 16.0);
                    const bool process = std::abs(p.x()) < 5.0 && p.y() > 62.0 && p.y() < 84.0;
                    if (vertebra <= 1.0 || process) label = phantom_label::bone;
                    for (const auto& kidney : kidneys)
                        if (kidney.value(p) <= 1.0) label = phantom_label::kidney;
                }
                volume.labels[static_cast<std::size_t>(g.linear_index(i, j, k))] = label;
            }
    return volume;
}

std::uint64_t SeededRandom::next()
{
    std::uint64_t z = (m_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

double SeededRandom::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

double SeededRandom::normal()
{
    if (m_has_spare) {
        m_has_spare = false;
        return m_spare;
    }
    double u1 = uniform();
    while (u1 <= 1e-300) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    m_spare = r * std::sin(2 * M_PI * u2);
    m_has_spare = true;
    return r * std::cos(2 * M_PI * u2);
}

ScalarImage synthesize_clean_mr_intensity(const LabelVolume& labels, const LabelRoles& roles, std::uint64_t seed)
{
    auto mean_of = [&](std::int32_t label) -> float {
        const std::string role = roles.role_of(label);
        if (role == "liver") return 520.f;
        if (role == "lesion") return 820.f;
        if (role == "vessel") return 120.f;
        if (role == "body") return 340.f;
        if (role == "bone") return 180.f;
        if (role == "kidney") return 660.f;
        return label == 0 ? 0.f : 400.f; // other tissues of a user's label map
    };
    ScalarImage image;
    image.geometry = labels.geometry;
    const auto& g = labels.geometry;
    image.values.resize(labels.labels.size());
    SeededRandom random(seed);
    // Bias: a few low-frequency cosines over the image box, random phases and weights.
    struct Wave { Vec3 k; double phase, weight; };
    std::vector<Wave> waves;
    const Vec3 extent = g.spacing.cwiseProduct(Vec3(double(g.size[0]), double(g.size[1]), double(g.size[2])));
    for (int w = 0; w < 4; ++w) {
        Vec3 dir(random.normal(), random.normal(), random.normal());
        dir.normalize();
        waves.push_back({M_PI * dir.cwiseQuotient(extent), 2 * M_PI * random.uniform(), 0.04 + 0.03 * random.uniform()});
    }
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                const Vec3 index = Vec3(double(i), double(j), double(k));
                const Vec3 p = g.spacing.cwiseProduct(index);
                double bias = 1.0;
                for (const auto& w : waves) bias += w.weight * std::cos(w.k.dot(p) + w.phase);
                image.values[v] = static_cast<float>(bias * mean_of(labels.labels[v]));
            }
    return image;
}

void add_mr_noise(ScalarImage& image, std::uint64_t seed)
{
    SeededRandom random(seed);
    const double sigma = 0.02 * 520.0;
    for (auto& value : image.values) {
        const double n1 = sigma * random.normal(), n2 = sigma * random.normal();
        value = static_cast<float>(std::hypot(double(value) + n1, n2)); // Rician magnitude
    }
}

ScalarImage synthesize_mr_intensity(const LabelVolume& labels, const LabelRoles& roles, std::uint64_t seed)
{
    ScalarImage image = synthesize_clean_mr_intensity(labels, roles, seed);
    add_mr_noise(image, seed ^ 0x9e3779b97f4a7c15ull);
    return image;
}

std::vector<VesselBranch> cirs057a_vessel_centrelines()
{
    std::vector<VesselBranch> out;
    for (const auto& t : vessel_tubes()) out.push_back({{t.a + liver_offset, t.b + liver_offset}, {t.ra, t.rb}});
    return out;
}

} // namespace physreg
