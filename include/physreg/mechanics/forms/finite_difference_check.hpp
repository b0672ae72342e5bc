// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The one finite-difference checker of the project (after ipc-toolkit's fd::compare_gradient): a
// Form's gradient against central differences of its value, and its Hessian product against central
// differences of its gradient, along coordinate and random directions.
//
// Errors are relative to the size of what is compared: |g·d − δf/δd| / max(‖g‖, |δf/δd|) per unit direction for
// the gradient, ‖H d − δg/δd‖ / max_d ‖H d‖ for the Hessian, so that a direction along which the
// derivative happens to vanish is not judged against zero. Piecewise-smooth forms (trilinear
// distance maps, contact switching on) may sit on a kink inside ±h: with `piecewise_smooth` a
// direction counts only where the difference with h and with h/2 agree, and the check says how many
// counted.
#include "physreg/mechanics/forms/form.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace physreg {

struct FiniteDifferenceOptions {
    double step = 1e-6;             ///< h, in the unknowns' units (scaled by ‖d‖ = 1 directions)
    std::size_t coordinate_directions = 24; ///< the first this many unknowns (of `variables`) are checked one by one
    int random_directions = 4;      ///< Gaussian directions, unit length
    std::uint32_t seed = 1;
    /// The unknowns that move (empty: all): held supports, free surface dofs of a reduced objective.
    std::vector<std::size_t> variables;
    bool piecewise_smooth = false;  ///< count a direction only where h and h/2 agree
    double smoothness_agreement = 1e-6; ///< relative agreement of the two differences that counts
};

struct FiniteDifferenceCheck {
    std::string form;
    double gradient_error = 0.0;     ///< the largest relative error over the directions counted
    double hessian_error = 0.0;      ///< 0 when the form has no Hessian (hessian_checked false)
    bool hessian_checked = false;
    int directions = 0;              ///< directions counted (gradient)
    int skipped = 0;                 ///< directions left out on a kink (piecewise_smooth)
    double gradient_norm = 0.0;      ///< ‖g‖ at x (a zero gradient checks nothing: see passed())
    /// Gradient (and Hessian, when checked) within `tolerance`, at least one direction counted and a
    /// non-zero gradient.
    bool passed(double gradient_tolerance, double hessian_tolerance) const;
    std::string summary() const;
};

/// Checks `form` at x. Throws Error when x has the wrong size or the form gives non-finite values.
FiniteDifferenceCheck check_derivatives(const Form& form, std::span<const double> x, const FiniteDifferenceOptions& options = {});

} // namespace physreg
