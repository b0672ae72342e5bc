// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 001's energies as Forms (mechanics/forms/form.hpp):
// - PairPotentialForm: the arctan pair forces of fixed pairs are −∇ of Σ ψ(d), ψ' the force law —
//   what accumulate_pair_forces spreads on the triangles' corners, with its exact Hessian (the
//   integrator uses the lumped bound ArctanForceLaw::stiffness_bound, ≥ its largest eigenvalue);
// - SurfaceAdjointForm: the adjoint method's J(f) = ½ mean (n·(x(u) − q))² + α ½ uᵀKu, u = K⁻¹f,
//   whose gradient takes one adjoint solve (first order: no Hessian).
#include "physreg/mechanics/forms/form.hpp"
#include "physreg/registration/surface/surface_adjoint.hpp"
#include "physreg/registration/surface/surface_matching.hpp"

#include <map>
#include <vector>

namespace physreg {

class PairPotentialForm : public Form {
public:
    /// Pairs as SurfaceMatcher::match gives them (their triangles and weights; the sources move
    /// with u from the rest positions `rest_mm`, 3 per node). Throws Error for a label with no stiffness.
    PairPotentialForm(std::vector<SurfacePair> pairs, const LabelledTriangles& source, std::map<std::int32_t, double> stiffness_n, ArctanForceLaw law,
                      const std::vector<double>& rest_mm);
    std::string name() const override { return "arctan pair potential"; }
    std::size_t size() const override { return m_rest.size(); }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;
    bool hessian_product(std::span<const double> u, std::span<const double> v, std::span<double> product) const override;

private:
    Vec3 gap(const SurfacePair& p, std::span<const double> u) const; ///< target − source at u
    std::vector<SurfacePair> m_pairs;
    const LabelledTriangles& m_source;
    std::map<std::int32_t, double> m_k;
    ArctanForceLaw m_law;
    const std::vector<double>& m_rest;
};

class SurfaceAdjointForm : public Form {
public:
    SurfaceAdjointForm(const VolumeMesh& mesh, const SurfaceMatcher& matcher, const LabelledPointCloud& cloud, AdjointSurfaceOptions options, double alpha,
                       const std::vector<double>* linearisation_mm = nullptr)
        : m_mesh(mesh), m_matcher(matcher), m_cloud(cloud), m_options(std::move(options)), m_alpha(alpha), m_linearisation(linearisation_mm)
    {
    }
    std::string name() const override { return "adjoint surface objective J(f)"; }
    std::size_t size() const override { return 3 * m_mesh.node_count(); }
    double value(std::span<const double> f) const override;
    void gradient(std::span<const double> f, std::span<double> g) const override;

private:
    const VolumeMesh& m_mesh;
    const SurfaceMatcher& m_matcher;
    const LabelledPointCloud& m_cloud;
    AdjointSurfaceOptions m_options;
    double m_alpha;
    const std::vector<double>* m_linearisation;
};

} // namespace physreg
