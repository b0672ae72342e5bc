// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// One interface for every energy the solvers and estimators minimise (after polyfem's Form): a
// scalar of a vector of unknowns, its gradient and — where the form has one — the product of its
// Hessian with a vector. Behind it: the elastic energy, tissue coupling, springs and supports,
// tool contact, the capsule membrane and vessel beams, the arctan pair potential of paper 001, the
// moduli prior and the segmentation objective of paper 002, and the reduced objectives whose
// gradients come from an adjoint solve. One finite-difference checker (finite_difference_check.hpp)
// verifies any of them, so a new energy gets its derivative test by being a Form.
//
// Units are the form's own (mechanical energies: mJ = N·mm of displacements in mm, gradient N,
// Hessian N/mm; the segmentation objective mm²); name() says what it is.
#include <cstddef>
#include <span>
#include <string>

namespace physreg {

class Form {
public:
    virtual ~Form() = default;
    /// What the energy is, for messages ("tissue coupling", "arctan pair potential").
    virtual std::string name() const = 0;
    /// The number of unknowns x.
    virtual std::size_t size() const = 0;
    virtual double value(std::span<const double> x) const = 0;
    /// ∂value/∂x at x into `gradient` (size() entries, overwritten).
    virtual void gradient(std::span<const double> x, std::span<double> gradient) const = 0;
    /// H(x) v into `product` (overwritten) when the form has a second derivative; false when it has
    /// none (first-order forms such as adjoint-reduced objectives).
    virtual bool hessian_product(std::span<const double> x, std::span<const double> v, std::span<double> product) const
    {
        (void)x, (void)v, (void)product;
        return false;
    }
};

} // namespace physreg
