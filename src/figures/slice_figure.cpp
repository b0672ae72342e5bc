// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/figures/slice_figure.hpp"

#include "physreg/core/error.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace physreg {
namespace {

Rgb role_colour(const std::string& role)
{
    if (role == "body") return {255, 150, 40};
    if (role == "liver") return {230, 40, 230};
    if (role == "lesion") return {255, 30, 30};
    if (role == "vessel") return {40, 230, 255};
    if (role == "bone") return {255, 240, 40};
    if (role == "kidney") return {40, 220, 60};
    return {160, 160, 255};
}

// A perceptually ordered map: dark blue → magenta → red → yellow, t ∈ [0, 1].
Rgb heat_colour(double t)
{
    t = std::clamp(t, 0.0, 1.0);
    const double stops[4][3] = {{20, 20, 120}, {180, 30, 140}, {240, 60, 30}, {255, 240, 60}};
    const double x = t * 3.0;
    const int i = std::min(2, static_cast<int>(x));
    const double f = x - i;
    Rgb c;
    for (int k = 0; k < 3; ++k) c[k] = static_cast<std::uint8_t>(stops[i][k] + f * (stops[i + 1][k] - stops[i][k]));
    return c;
}

} // namespace

Canvas render_orthogonal_slices(const ScalarImage& intensity, const LabelVolume& labels, const LabelRoles& roles,
                                const LandmarkSet& truth, const LandmarkSet& predicted, const SliceFigureOptions& options)
{
    const auto& g = labels.geometry;
    if (intensity.geometry.size != g.size) fail("slice figure: intensity and label images differ in size");
    if (!(options.pixels_per_mm > 0.0) || options.pixels_per_mm > 20.0) fail("slice figure: {} pixels per mm", options.pixels_per_mm);
    if (options.heat && options.heat->geometry.size != g.size) fail("slice figure: the colour map and the label image differ in size");
    if (options.heat && !(options.heat_max > 0)) fail("slice figure: colour map maximum must be > 0");
    const int bar_height = options.heat ? 40 : 0;
    // Physical bounding box of the image.
    Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
    for (int corner = 0; corner < 8; ++corner) {
        Vec3 index;
        for (int a = 0; a < 3; ++a) index[a] = ((corner >> a) & 1) ? double(g.size[a]) - 0.5 : -0.5;
        const Vec3 p = g.index_to_physical(index);
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    std::vector<float> sorted(intensity.values.begin(), intensity.values.end());
    const std::size_t rank = static_cast<std::size_t>(0.995 * static_cast<double>(sorted.size() - 1));
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(rank), sorted.end());
    const float white = std::max(1e-6f, sorted[rank]);
    auto voxel = [&](const Vec3& p) -> long {
        const Vec3 index = g.physical_to_index(p);
        std::int64_t ijk[3];
        for (int a = 0; a < 3; ++a) {
            ijk[a] = std::lround(index[a]);
            if (ijk[a] < 0 || ijk[a] >= g.size[a]) return -1;
        }
        return static_cast<long>(g.linear_index(ijk[0], ijk[1], ijk[2]));
    };
    const double s = options.pixels_per_mm;
    // Panel: horizontal axis h (image +x direction), vertical axis v (image +y direction = down).
    struct Panel { int h, v; bool flip_h, flip_v; int normal; const char* name; };
    const Panel panels[] = {{0, 1, false, false, 2, "AXIAL"}, {0, 2, false, true, 1, "CORONAL"}, {1, 2, false, true, 0, "SAGITTAL"}};
    const int title_height = 22, gap = 8;
    int width = gap, height = 0;
    for (const auto& p : panels) {
        width += static_cast<int>(std::ceil((hi[p.h] - lo[p.h]) * s)) + gap;
        height = std::max(height, static_cast<int>(std::ceil((hi[p.v] - lo[p.v]) * s)));
    }
    Canvas canvas(width, height + title_height + 2 * gap + bar_height, {20, 20, 20});
    canvas.text(gap, 6, options.title, {255, 255, 255}, 2);
    std::map<std::string, const Landmark*> predicted_by_name;
    for (const auto& l : predicted) predicted_by_name[l.name] = &l;
    int x0 = gap;
    for (const auto& p : panels) {
        const int w = static_cast<int>(std::ceil((hi[p.h] - lo[p.h]) * s)), h = static_cast<int>(std::ceil((hi[p.v] - lo[p.v]) * s));
        const int y0 = title_height + gap;
        auto to_physical = [&](double px, double py) {
            Vec3 q = options.centre;
            q[p.h] = p.flip_h ? hi[p.h] - (px + 0.5) / s : lo[p.h] + (px + 0.5) / s;
            q[p.v] = p.flip_v ? hi[p.v] - (py + 0.5) / s : lo[p.v] + (py + 0.5) / s;
            return q;
        };
        auto to_pixel = [&](const Vec3& q, double& px, double& py) {
            px = p.flip_h ? (hi[p.h] - q[p.h]) * s - 0.5 : (q[p.h] - lo[p.h]) * s - 0.5;
            py = p.flip_v ? (hi[p.v] - q[p.v]) * s - 0.5 : (q[p.v] - lo[p.v]) * s - 0.5;
        };
        std::vector<long> index(static_cast<std::size_t>(w) * h);
        for (int py = 0; py < h; ++py)
            for (int px = 0; px < w; ++px) index[static_cast<std::size_t>(py) * w + px] = voxel(to_physical(px, py));
        for (int py = 0; py < h; ++py)
            for (int px = 0; px < w; ++px) {
                const long v = index[static_cast<std::size_t>(py) * w + px];
                if (v < 0) continue;
                if (options.heat) {
                    const float value = options.heat->values[static_cast<std::size_t>(v)];
                    if (std::isfinite(value)) {
                        canvas.set(x0 + px, y0 + py, heat_colour(double(value) / options.heat_max));
                        continue;
                    }
                }
                const auto grey = static_cast<std::uint8_t>(std::clamp(255.0f * intensity.values[static_cast<std::size_t>(v)] / white, 0.f, 255.f));
                canvas.set(x0 + px, y0 + py, {grey, grey, grey});
            }
        // Contours: a pixel whose label differs from its right or lower neighbour's.
        for (int py = 0; py + 1 < h; ++py)
            for (int px = 0; px + 1 < w; ++px) {
                const long v = index[static_cast<std::size_t>(py) * w + px];
                if (v < 0) continue;
                const auto here = labels.labels[static_cast<std::size_t>(v)];
                for (const long n : {index[static_cast<std::size_t>(py) * w + px + 1], index[static_cast<std::size_t>(py + 1) * w + px]}) {
                    if (n < 0) continue;
                    const auto there = labels.labels[static_cast<std::size_t>(n)];
                    if (there == here) continue;
                    // Colour of the inner tissue: the one that is not body/background when possible.
                    std::string role = roles.role_of(here);
                    const std::string other = roles.role_of(there);
                    if (role.empty() || role == "body") role = other.empty() ? role : other;
                    canvas.set(x0 + px, y0 + py, role_colour(role));
                }
            }
        for (const auto& l : truth) {
            if (std::abs(l.position[p.normal] - options.centre[p.normal]) > options.landmark_slab_mm) continue;
            double px, py;
            to_pixel(l.position, px, py);
            canvas.cross(x0 + px, y0 + py, 4, {60, 255, 60}, 2);
            if (const auto it = predicted_by_name.find(l.name); it != predicted_by_name.end()) {
                double qx, qy;
                to_pixel(it->second->position, qx, qy);
                canvas.line(x0 + px, y0 + py, x0 + qx, y0 + qy, {255, 255, 0});
                canvas.circle(x0 + qx, y0 + qy, 4, {255, 40, 40});
            }
        }
        canvas.text(x0 + 4, y0 + 4, p.name, {255, 255, 255}, 1);
        x0 += w + gap;
    }
    if (options.heat) {
        // Colour bar with its scale under the panels.
        const int y = title_height + 2 * gap + height + 4, bar_w = std::min(400, width - 2 * gap - 160);
        for (int px = 0; px < bar_w; ++px) canvas.fill_rect(gap + px, y, gap + px, y + 12, heat_colour(double(px) / double(bar_w - 1)));
        for (int t = 0; t <= 4; ++t) {
            const int px = gap + t * (bar_w - 1) / 4;
            canvas.line(px, y + 12, px, y + 16, {255, 255, 255});
            canvas.text(px - 8, y + 19, fmt::format("{:.2g}", options.heat_max * t / 4.0), {255, 255, 255});
        }
        canvas.text(gap + bar_w + 12, y + 3, options.heat_label, {255, 255, 255});
    }
    return canvas;
}

} // namespace physreg
