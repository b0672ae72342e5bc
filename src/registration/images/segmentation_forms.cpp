// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/images/segmentation_forms.hpp"

#include "physreg/core/error.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace physreg {
namespace {

Eigen::Map<const Eigen::VectorXd> as_vector(std::span<const double> v) { return {v.data(), static_cast<Eigen::Index>(v.size())}; }

} // namespace

double SegmentationObjectiveForm::value(std::span<const double> u) const { return m_objective.evaluate(as_vector(u), nullptr); }

void SegmentationObjectiveForm::gradient(std::span<const double> u, std::span<double> g) const
{
    Eigen::VectorXd gradient;
    m_objective.evaluate(as_vector(u), &gradient);
    std::copy(gradient.begin(), gradient.end(), g.begin());
}

std::string SegmentationBoundaryForm::name() const
{
    return fmt::format("segmentation objective of the boundary {} (adjoint)", m_mode == BoundaryParametrisation::nodal_forces ? "forces" : "displacements");
}

double SegmentationBoundaryForm::value(std::span<const double> x) const
{
    return evaluate_segmentation_gradient(m_model, m_objective, m_force_nodes, m_mode, m_scale, as_vector(x)).objective_mm2;
}

void SegmentationBoundaryForm::gradient(std::span<const double> x, std::span<double> g) const
{
    const SegmentationGradient r = evaluate_segmentation_gradient(m_model, m_objective, m_force_nodes, m_mode, m_scale, as_vector(x));
    std::copy(r.d_force.begin(), r.d_force.end(), g.begin());
}

SegmentationModulusForm::SegmentationModulusForm(LinearElasticModel& model, const SegmentationObjective& objective, std::vector<std::int32_t> force_nodes,
                                                 BoundaryParametrisation parametrisation, double force_scale_n_mm, Eigen::VectorXd x,
                                                 std::vector<double> base_moduli_pa)
    : m_model(model), m_objective(objective), m_force_nodes(std::move(force_nodes)), m_mode(parametrisation), m_scale(force_scale_n_mm), m_x(std::move(x)),
      m_base(std::move(base_moduli_pa))
{
    if (m_base.size() != model.young_moduli_pa().size())
        fail("segmentation objective of the log-moduli: {} base moduli for {} structures", m_base.size(), model.young_moduli_pa().size());
}

SegmentationGradient SegmentationModulusForm::evaluate(std::span<const double> y) const
{
    std::vector<double> e = m_base;
    for (std::size_t j = 0; j < e.size(); ++j) e[j] *= std::exp(y[j]);
    m_model.set_young_moduli(e);
    return evaluate_segmentation_gradient(m_model, m_objective, m_force_nodes, m_mode, m_scale, m_x);
}

double SegmentationModulusForm::value(std::span<const double> y) const { return evaluate(y).objective_mm2; }

void SegmentationModulusForm::gradient(std::span<const double> y, std::span<double> g) const
{
    const SegmentationGradient r = evaluate(y);
    std::copy(r.d_log_modulus.begin(), r.d_log_modulus.end(), g.begin());
}

ModuliPriorForm::ModuliPriorForm(double weight_mm2, std::vector<double> mean_log_moduli, std::vector<std::size_t> estimated)
    : m_weight(weight_mm2), m_mean(std::move(mean_log_moduli)), m_estimated(std::move(estimated))
{
    if (!(m_weight >= 0) || !std::isfinite(m_weight)) fail("moduli prior: weight {} mm² must be ≥ 0 and finite", m_weight);
    for (auto j : m_estimated)
        if (j >= m_mean.size()) fail("moduli prior: structure {} has no prior mean (there are {})", j, m_mean.size());
}

double ModuliPriorForm::value(std::span<const double> y) const
{
    if (m_weight == 0.0) return 0.0;
    double value = 0.0;
    for (auto j : m_estimated) {
        const double r = y[j] - m_mean[j];
        value += 0.5 * m_weight * r * r;
    }
    return value;
}

void ModuliPriorForm::gradient(std::span<const double> y, std::span<double> g) const
{
    std::fill(g.begin(), g.end(), 0.0);
    if (m_weight == 0.0) return;
    for (auto j : m_estimated) g[j] = m_weight * (y[j] - m_mean[j]);
}

bool ModuliPriorForm::hessian_product(std::span<const double>, std::span<const double> v, std::span<double> product) const
{
    std::fill(product.begin(), product.end(), 0.0);
    for (auto j : m_estimated) product[j] = m_weight * v[j];
    return true;
}

} // namespace physreg
