// SPDX-License-Identifier: GPL-3.0-or-later
// Face contact (issue 46 item 1): a sphere pressed up to 1.5× its radius into a block between the
// nodes of its top face must stay in front of the skin; node-to-surface contact alone lets it slip
// between the nodes. And the face samples themselves: shape functions that sum to one, an
// allowance equal to a chord's sag.
#include "mechanics_fixtures.hpp"
#include "physreg/core/error.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace physreg;
using namespace physreg::test;

namespace {

struct Pressed {
    bool converged = false;
    double face_centre_z = 0.0; ///< the deformed top face under the tool: its corners' mean, mm
    double sphere_z = 0.0;      ///< the sphere's centre at the end, mm
};

// A 60 × 60 × 40 mm block of 5 mm hexahedra (E 3 kPa, ν 0.45), base held; a 10 mm sphere over the
// centre of the top face [30, 35]² (its corners 3.5 mm from the axis) pressed `depth` mm past
// first contact.
Pressed press_between_nodes(bool face_contact, double depth)
{
    const VolumeMesh mesh = block_mesh(12, 12, 8, 5.0);
    const TledModel model(mesh, one_tissue(3e3, 0.45), {});
    const double r = 10.0, top = 40.0;
    const Vec3 start(32.5, 32.5, top + r + 0.5), end(32.5, 32.5, top + r - depth);
    TledSolver<double> solver(model);
    solver.set_loads(base_held_sphere_press(mesh, r, {start, end}));
    EquilibriumOptions options;
    options.face_contact = face_contact;
    options.ramp_iterations = 4000;
    options.max_iterations = 100000;
    Pressed out;
    out.converged = solver.solve_equilibrium(options, 1.0).converged();
    const auto u = solver.displacement_mm();
    Vec3 centre = Vec3::Zero();
    for (const Vec3& corner : {Vec3(30, 30, top), Vec3(35, 30, top), Vec3(35, 35, top), Vec3(30, 35, top)}) {
        const auto n = static_cast<std::size_t>(node_at(mesh, corner));
        centre += 0.25 * (mesh.nodes[n] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]));
    }
    out.face_centre_z = centre.z();
    out.sphere_z = end.z();
    return out;
}

} // namespace

TEST(FaceContact, ASphereAsDeepAsOneAndAHalfRadiiStaysInFrontOfTheSkin)
{
    for (const double depth : {10.0, 15.0}) {
        const Pressed faces = press_between_nodes(true, depth);
        ASSERT_TRUE(faces.converged) << depth;
        // The face under the tool lies in front of the sphere: below its centre by more than half
        // the radius (its front is one radius below; the penalty lets a face sink a little).
        EXPECT_LT(faces.face_centre_z, faces.sphere_z - 5.0) << depth << " mm: face at " << faces.face_centre_z << " mm, centre at " << faces.sphere_z;
        // Nodes alone: the sphere slips between the face's four corners, which spring back
        // round it (the face ends less than half a radius below the centre, or above it).
        const Pressed nodes = press_between_nodes(false, depth);
        EXPECT_GT(nodes.face_centre_z, nodes.sphere_z - 5.0) << depth << " mm: node contact alone held the tool; the test no longer shows the failure";
    }
}

TEST(FaceContact, TwiceTheRadiusFoldsAnElementAndSaysSo)
{
    // Deeper than the model's cells can follow: an error naming the element, never a tool that
    // silently went through.
    try {
        const Pressed p = press_between_nodes(true, 20.0);
        EXPECT_LT(p.face_centre_z, p.sphere_z) << "the tool went through the skin without an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("inverted"), std::string::npos) << e.what();
    }
}

TEST(FaceContact, SamplesSumToOneAndMaySinkByAChordsSag)
{
    Indenter sphere;
    sphere.radius_mm = 10.0;
    sphere.path = {Vec3::Zero()};
    // A 6 × 6 mm square: span (diagonal) 8.49 mm → sag 10 − √(100 − 18) = 0.945 mm; grid ⌈8.49 / 2.5⌉ = 4.
    const std::array<Vec3, 4> square{Vec3(0, 0, 0), Vec3(6, 0, 0), Vec3(6, 6, 0), Vec3(0, 6, 0)};
    const FaceContactSamples s = face_contact_samples(sphere, square, 4);
    EXPECT_EQ(s.weights.size(), 16u);
    EXPECT_NEAR(s.allowance_mm, 10.0 - std::sqrt(100.0 - 18.0), 1e-12);
    for (const auto& w : s.weights) EXPECT_NEAR(w[0] + w[1] + w[2] + w[3], 1.0, 1e-12);
    // A face larger than the sphere: the allowance stops at a fifth of the radius.
    const std::array<Vec3, 4> large{Vec3(0, 0, 0), Vec3(30, 0, 0), Vec3(30, 30, 0), Vec3(0, 30, 0)};
    const FaceContactSamples l = face_contact_samples(sphere, large, 4);
    EXPECT_DOUBLE_EQ(l.allowance_mm, 2.0);
    EXPECT_EQ(l.weights.size(), 64u); // capped at 8 × 8
    // A triangle: n² sub-triangle centroids (n = 2 → 4), weights in [0, 1].
    const std::array<Vec3, 4> tri{Vec3(0, 0, 0), Vec3(3, 0, 0), Vec3(0, 3, 0), Vec3::Zero()}; // longest edge 4.24 mm
    const FaceContactSamples t = face_contact_samples(sphere, tri, 3);
    EXPECT_EQ(t.weights.size(), 4u);
    for (const auto& w : t.weights) {
        EXPECT_NEAR(w[0] + w[1] + w[2], 1.0, 1e-12);
        EXPECT_GE(std::min({w[0], w[1], w[2]}), 0.0);
    }
    // A plane never needs them: a face between nodes outside a half-space is outside it.
    Indenter plane = sphere;
    plane.shape = IndenterShape::plane;
    EXPECT_TRUE(face_contact_samples(plane, square, 4).weights.empty());
}
