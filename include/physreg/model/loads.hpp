// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Loads and constraints of a TLED simulation: constrained node sets (fixed or prescribed
// displacement), rigid indenters pressing through frictionless contact, and nodal forces.
// Everything scales with a load factor s ∈ [0, 1]; in a dynamic run s(t) follows a smooth ramp.
#include "physreg/core/types.hpp"

#include <array>
#include <string>
#include <vector>

namespace physreg {

/// 0 → 1 with zero velocity and acceleration at both ends: 10τ³ − 15τ⁴ + 6τ⁵.
double smooth_step(double tau);

struct NodeConstraint {
    std::string name;
    std::vector<std::int32_t> nodes;
    std::array<bool, 3> dofs{true, true, true}; ///< which components are constrained
    Vec3 displacement_mm = Vec3::Zero();        ///< at load factor 1 (zero: fixed nodes)
};

enum class IndenterShape { sphere, cylinder, plane, box };
IndenterShape parse_indenter_shape(const std::string& text);

/// A rigid tool. Its reference point (sphere centre, a point of the cylinder axis or of the
/// plane, box centre) moves along `path`, piecewise linearly in the load factor.
struct Indenter {
    std::string name;
    IndenterShape shape = IndenterShape::sphere;
    std::vector<Vec3> path;               ///< ≥ 1 positions, mm; s = 0 at the first, 1 at the last
    double radius_mm = 0.0;               ///< sphere, cylinder
    Vec3 axis = Vec3::UnitZ();            ///< cylinder axis; plane normal (tissue stays on its + side)
    Vec3 half_extents_mm = Vec3::Zero();  ///< box, in its own axes
    Mat3 rotation = Mat3::Identity();     ///< box axes (columns) in LPS

    Vec3 position(double load_factor) const;
    /// If `x` is inside the tool at load factor s, the closest point of its surface and the
    /// outward normal there; otherwise false.
    bool push_out(const Vec3& x, double load_factor, Vec3& surface_point, Vec3& normal) const;
    /// The closest point of the tool's surface to `x` (inside or outside) and the outward normal.
    void closest_surface_point(const Vec3& x, double load_factor, Vec3& surface_point, Vec3& normal) const;
    /// Largest distance from the reference point to a point of the tool, mm (infinite for the
    /// unbounded cylinder and plane): nodes farther than this from the reference point cannot touch it.
    double reach_mm() const;
    void validate() const;
};

/// Where a tool may press a surface face between its nodes. Node-to-surface contact holds a
/// surface's nodes outside a tool, not the faces between them: pressed deeper than about its
/// radius, a sphere stretches the skin until the nodes slide round it and it slips between them.
/// So contact also samples each face near a tool (a grid on its current shape, about a quarter of
/// the tool's radius apart); a sample may sink into the tool by the sag of a chord across the face
/// (what a face whose nodes all lie on a sphere shows), at most a fifth of the radius, and no more.
struct FaceContactSamples {
    std::vector<std::array<double, 4>> weights; ///< per sample: the corners' shape functions (Σ = 1)
    double allowance_mm = 0.0;                  ///< how far a sample may lie inside the tool
};
/// The samples of a face with `count` (3 or 4, cyclic order) corners at `corners` (mm) against
/// `tool`; none for a plane (a face between nodes outside a half-space is outside it).
FaceContactSamples face_contact_samples(const Indenter& tool, const std::array<Vec3, 4>& corners, int count);
/// The face's size: its longer diagonal (quad) or longest edge (triangle), mm.
double face_span_mm(const std::array<Vec3, 4>& corners, int count);

struct Loads {
    std::vector<NodeConstraint> constraints;
    std::vector<Indenter> indenters;
    std::vector<double> external_forces_n; ///< 3 per node at load factor 1, or empty
    double ramp_time_s = 0.0;              ///< dynamic runs: time to reach load factor 1

    /// Throws Error naming the load for node ids out of range, NaN values, bad shapes.
    void validate(std::size_t node_count) const;
    double load_factor(double time_s) const { return ramp_time_s > 0 ? smooth_step(time_s / ramp_time_s) : 1.0; }
};

} // namespace physreg
