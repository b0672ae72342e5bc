// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The registry of Form checks (issue 43 item 3): each test file registers, next to its fixtures,
// the forms it builds and the point where they are checked; test_forms.cpp runs the one
// finite-difference checker over every registered case and fails when a Form of the library has none.
#include "physreg/mechanics/forms/finite_difference_check.hpp"

#include <algorithm>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace physreg::test {

struct FormCheckResult {
    FiniteDifferenceCheck check;
    double gradient_tolerance = 1e-6;
    /// The Hessian's tolerance when the form offers one (infinity: its second derivative is an
    /// approximation there, e.g. the rotated co-rotational stiffness away from rest).
    double hessian_tolerance = 1e-6;
    bool expect_hessian = true; ///< the form must offer a Hessian product
    int min_directions = 1;     ///< piecewise-smooth forms: directions that must count
    bool expect_gradient = true; ///< false at a stationary point (rest), where only the Hessian is checked
};

struct FormCase {
    std::string form_class; ///< the Form subclass it covers ("ElasticForm")
    std::string name;       ///< what is checked, for the test's name
    std::function<FormCheckResult()> run;
};

std::vector<FormCase>& form_cases();

/// Two checks of one form (at two points) as one: directions and skips add up, errors are the worst.
inline FiniteDifferenceCheck merged(const FiniteDifferenceCheck& a, const FiniteDifferenceCheck& b)
{
    FiniteDifferenceCheck m = b;
    m.directions += a.directions;
    m.skipped += a.skipped;
    if (a.directions > 0) m.gradient_error = std::max(a.gradient_error, b.gradient_error);
    m.hessian_error = std::max(a.hessian_error, b.hessian_error);
    m.gradient_norm = std::min(a.gradient_norm, b.gradient_norm);
    return m;
}

/// A static registration: `const RegisterFormCase c{"ElasticForm", "grid hexahedra, neo-Hookean", [] { … }};`
struct RegisterFormCase {
    RegisterFormCase(std::string form_class, std::string name, std::function<FormCheckResult()> run)
    {
        form_cases().push_back({std::move(form_class), std::move(name), std::move(run)});
    }
};

} // namespace physreg::test
