// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/mechanics/forms/finite_difference_check.hpp"

#include "physreg/core/error.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace physreg {
namespace {

double norm(std::span<const double> v)
{
    double s = 0.0;
    for (double e : v) s += e * e;
    return std::sqrt(s);
}

void require_finite(std::span<const double> v, const std::string& form, const char* what)
{
    for (double e : v)
        if (!std::isfinite(e)) fail("finite-difference check of {}: its {} is not finite", form, what);
}

} // namespace

bool FiniteDifferenceCheck::passed(double gradient_tolerance, double hessian_tolerance) const
{
    return directions > 0 && gradient_norm > 0.0 && gradient_error <= gradient_tolerance && (!hessian_checked || hessian_error <= hessian_tolerance);
}

std::string FiniteDifferenceCheck::summary() const
{
    return fmt::format("{}: gradient error {:.3g} over {} direction(s) ({} on a kink), |g| {:.3g}; Hessian {}", form, gradient_error, directions,
                       skipped, gradient_norm, hessian_checked ? fmt::format("error {:.3g}", hessian_error) : std::string("not offered"));
}

FiniteDifferenceCheck check_derivatives(const Form& form, std::span<const double> x, const FiniteDifferenceOptions& options)
{
    const std::size_t n = form.size();
    FiniteDifferenceCheck out;
    out.form = form.name();
    if (x.size() != n) fail("finite-difference check of {}: {} unknowns given, the form has {}", out.form, x.size(), n);
    if (!(options.step > 0) || !std::isfinite(options.step)) fail("finite-difference check of {}: step {} must be positive", out.form, options.step);
    std::vector<std::size_t> variables = options.variables;
    if (variables.empty())
        for (std::size_t i = 0; i < n; ++i) variables.push_back(i);
    for (auto i : variables)
        if (i >= n) fail("finite-difference check of {}: unknown {} is not among its {}", out.form, i, n);

    std::vector<double> g(n), h_d(n), g_plus(n), g_minus(n), at(x.begin(), x.end());
    form.gradient(x, g);
    require_finite(g, out.form, "gradient");
    out.gradient_norm = norm(g);

    // The directions: unit coordinates first, then unit Gaussian ones over the moving unknowns.
    std::vector<std::vector<double>> directions;
    for (std::size_t k = 0; k < std::min(options.coordinate_directions, variables.size()); ++k) {
        std::vector<double> d(n, 0.0);
        d[variables[k]] = 1.0;
        directions.push_back(std::move(d));
    }
    std::mt19937 random(options.seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    for (int r = 0; r < options.random_directions; ++r) {
        std::vector<double> d(n, 0.0);
        for (auto i : variables) d[i] = normal(random);
        const double length = norm(d);
        if (length == 0.0) continue;
        for (auto& e : d) e /= length;
        directions.push_back(std::move(d));
    }

    const auto value_along = [&](const std::vector<double>& d, double t) {
        for (std::size_t i = 0; i < n; ++i) at[i] = x[i] + t * d[i];
        const double v = form.value(at);
        if (!std::isfinite(v)) fail("finite-difference check of {}: its value is not finite", out.form);
        return v;
    };
    const auto gradient_along = [&](const std::vector<double>& d, double t, std::vector<double>& into) {
        for (std::size_t i = 0; i < n; ++i) at[i] = x[i] + t * d[i];
        form.gradient(at, into);
        require_finite(into, out.form, "gradient");
    };
    const double h = options.step;
    double hessian_scale = 0.0, hessian_difference = 0.0;
    out.hessian_checked = form.hessian_product(x, directions.empty() ? std::vector<double>(n, 0.0) : directions.front(), h_d);
    for (const auto& d : directions) {
        const double full = (value_along(d, h) - value_along(d, -h)) / (2 * h);
        double difference = full;
        if (options.piecewise_smooth) {
            const double half = (value_along(d, h / 2) - value_along(d, -h / 2)) / h;
            if (std::abs(full - half) > options.smoothness_agreement * std::max(std::abs(half), 1e-300)) {
                ++out.skipped;
                continue;
            }
            difference = half;
        }
        double exact = 0.0;
        for (std::size_t i = 0; i < n; ++i) exact += g[i] * d[i];
        ++out.directions;
        // Relative to ‖g‖ (|g·d| ≤ ‖g‖ for a unit d), or to the difference itself where g vanishes (rest).
        const double relative_to = std::max({out.gradient_norm, std::abs(difference), 1e-300});
        out.gradient_error = std::max(out.gradient_error, std::abs(exact - difference) / relative_to);
        if (!out.hessian_checked) continue;
        form.hessian_product(x, d, h_d);
        require_finite(h_d, out.form, "Hessian product");
        gradient_along(d, h, g_plus);
        gradient_along(d, -h, g_minus);
        double squares = 0.0, scale = 0.0;
        for (std::size_t i = 0; i < n; ++i) {
            const double e = h_d[i] - (g_plus[i] - g_minus[i]) / (2 * h);
            squares += e * e;
            scale += h_d[i] * h_d[i];
        }
        hessian_difference = std::max(hessian_difference, std::sqrt(squares));
        hessian_scale = std::max(hessian_scale, std::sqrt(scale));
    }
    if (out.hessian_checked) out.hessian_error = hessian_difference / std::max(hessian_scale, 1e-300);
    return out;
}

} // namespace physreg
