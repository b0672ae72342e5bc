// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Elements that act on a model's own nodes besides its volume elements — paper 001's capsule
// membrane and embedded vessel beams. The implicit integrator adds their forces and (rotated)
// stiffness to the model's; the assembler's sparsity pattern includes their stencils.
#include <cstdint>
#include <vector>

namespace physreg {

class StiffnessAssembler;

class AuxiliaryElements {
public:
    virtual ~AuxiliaryElements() = default;
    /// Node groups coupled by one element each: every pair within a group gets a pattern entry.
    virtual std::vector<std::vector<std::int32_t>> stencils() const = 0;
    /// Adds the internal forces (N) at displacement u (mm, 3 per model node) into f; returns the energy (mJ).
    virtual double add_forces(const double* u, double* f) const = 0;
    /// Adds the stiffness (N/mm) into `values` of a matrix in `assembler`'s pattern.
    virtual void add_stiffness(const double* u, const StiffnessAssembler& assembler, double* values) const = 0;
};

} // namespace physreg
