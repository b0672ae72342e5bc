// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 002's energies as Forms (mechanics/forms/form.hpp):
// - SegmentationObjectiveForm: the data term Φ(u) (mm²) of the nodal displacements;
// - SegmentationBoundaryForm: Φ of the boundary unknowns x through the elastic solve u = K⁻¹ F(x),
//   its gradient by the adjoint (evaluate_segmentation_gradient);
// - SegmentationModulusForm: Φ of the log-moduli offsets y (E_j = E_j⁰ e^(y_j)) at fixed x, its
//   gradient by the same adjoint;
// - ModuliPriorForm: the log-normal prior Π(y) = ½ w Σ_(j estimated) (y_j − m_j)² on log-moduli,
//   which the alternation adds to Φ.
#include "physreg/mechanics/forms/form.hpp"
#include "physreg/registration/images/segmentation_registration.hpp"

#include <vector>

namespace physreg {

class SegmentationObjectiveForm : public Form {
public:
    SegmentationObjectiveForm(const SegmentationObjective& objective, std::size_t node_count) : m_objective(objective), m_node_count(node_count) {}
    std::string name() const override { return m_objective.symmetric() ? "segmentation objective (symmetric)" : "segmentation objective"; }
    std::size_t size() const override { return 3 * m_node_count; }
    double value(std::span<const double> u) const override;
    void gradient(std::span<const double> u, std::span<double> g) const override;

private:
    const SegmentationObjective& m_objective;
    std::size_t m_node_count;
};

class SegmentationBoundaryForm : public Form {
public:
    SegmentationBoundaryForm(const LinearElasticModel& model, const SegmentationObjective& objective, std::vector<std::int32_t> force_nodes,
                             BoundaryParametrisation parametrisation, double force_scale_n_mm)
        : m_model(model), m_objective(objective), m_force_nodes(std::move(force_nodes)), m_mode(parametrisation), m_scale(force_scale_n_mm)
    {
    }
    std::string name() const override;
    std::size_t size() const override { return 3 * m_force_nodes.size(); }
    double value(std::span<const double> x) const override;
    void gradient(std::span<const double> x, std::span<double> g) const override;

private:
    const LinearElasticModel& m_model;
    const SegmentationObjective& m_objective;
    std::vector<std::int32_t> m_force_nodes;
    BoundaryParametrisation m_mode;
    double m_scale;
};

/// Sets the model's moduli at every evaluation (the model is shared: not thread-safe).
class SegmentationModulusForm : public Form {
public:
    SegmentationModulusForm(LinearElasticModel& model, const SegmentationObjective& objective, std::vector<std::int32_t> force_nodes,
                            BoundaryParametrisation parametrisation, double force_scale_n_mm, Eigen::VectorXd x, std::vector<double> base_moduli_pa);
    std::string name() const override { return "segmentation objective of the log-moduli"; }
    std::size_t size() const override { return m_base.size(); }
    double value(std::span<const double> y) const override;
    void gradient(std::span<const double> y, std::span<double> g) const override;

private:
    SegmentationGradient evaluate(std::span<const double> y) const;
    LinearElasticModel& m_model;
    const SegmentationObjective& m_objective;
    std::vector<std::int32_t> m_force_nodes;
    BoundaryParametrisation m_mode;
    double m_scale;
    Eigen::VectorXd m_x;
    std::vector<double> m_base;
};

class ModuliPriorForm : public Form {
public:
    ModuliPriorForm() = default;
    /// weight w (mm², ≥ 0; 0: no prior), the mean log-modulus of every structure, and the structures it acts on.
    ModuliPriorForm(double weight_mm2, std::vector<double> mean_log_moduli, std::vector<std::size_t> estimated);
    std::string name() const override { return "log-normal moduli prior"; }
    std::size_t size() const override { return m_mean.size(); }
    double value(std::span<const double> log_moduli) const override;
    void gradient(std::span<const double> log_moduli, std::span<double> g) const override;
    bool hessian_product(std::span<const double> log_moduli, std::span<const double> v, std::span<double> product) const override;
    double weight_mm2() const { return m_weight; }

private:
    double m_weight = 0.0;
    std::vector<double> m_mean;
    std::vector<std::size_t> m_estimated;
};

} // namespace physreg
