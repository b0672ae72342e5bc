// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/registration/compression/estimation.hpp"

#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/core/thread_governor.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/dataset.hpp"

#include <nlopt.hpp>
#include <omp.h>

#include <chrono>
#include <cmath>

namespace physreg {

std::vector<CompressionCase> compression_cases(const PhantomDataset& dataset, const std::vector<std::string>& names)
{
    std::vector<CompressionCase> out;
    for (const auto& name : names) {
        const DatasetState& state = dataset.state(name);
        if (!state.tool) fail("dataset '{}': state '{}' is not a tool compression (it is {})", dataset.directory.string(), name, state.kind);
        const auto it = state.files.find("landmarks");
        if (it == state.files.end()) fail("dataset '{}': compression '{}' has no landmarks", dataset.directory.string(), name);
        CompressionCase c{name, *state.tool, read_landmarks(dataset.path(it->second))};
        if (c.truth.empty()) fail("dataset '{}': compression '{}' has no landmarks ('{}' is empty)", dataset.directory.string(), name, it->second);
        out.push_back(std::move(c));
    }
    return out;
}

void EstimationOptions::validate() const
{
    if (!(k_min_n_per_m > 0) || !(k_max_n_per_m > k_min_n_per_m) || !std::isfinite(k_max_n_per_m))
        fail("coupling stiffness bounds must satisfy 0 < min < max < ∞ N/m (got {} … {})", k_min_n_per_m, k_max_n_per_m);
    if (!(modulus_min_pa > 0) || !(modulus_max_pa > modulus_min_pa) || !std::isfinite(modulus_max_pa))
        fail("Young's modulus bounds must satisfy 0 < min < max < ∞ Pa (got {} … {})", modulus_min_pa, modulus_max_pa);
    if (!(body_modulus_min_pa > 0) || !(body_modulus_max_pa > body_modulus_min_pa) || !std::isfinite(body_modulus_max_pa))
        fail("body modulus bounds must satisfy 0 < min < max < ∞ Pa (got {} … {})", body_modulus_min_pa, body_modulus_max_pa);
    if (algorithm != "bobyqa" && algorithm != "neldermead") fail("optimiser '{}' is not one of bobyqa, neldermead", algorithm);
    if (max_evaluations < 1) fail("max evaluations must be ≥ 1 (got {})", max_evaluations);
    if (!(x_tolerance_decades > 0)) fail("parameter tolerance must be > 0 decades");
}

std::vector<std::pair<std::string, TreReport>> evaluate_cases(const LabelVolume& rest_labels, const LabelRoles& roles,
                                                              const ModelParameters& parameters, const LandmarkSet& rest_landmarks,
                                                              const std::vector<CompressionCase>& cases, const PredictionOptions& options,
                                                              std::vector<std::vector<double>>* warm)
{
    return evaluate_cases(build_liver_model(rest_labels, roles, parameters, "rest labels"), parameters, rest_landmarks, cases, options, warm);
}

std::vector<std::pair<std::string, TreReport>> evaluate_cases(const LiverModel& model, const ModelParameters& parameters,
                                                              const LandmarkSet& rest_landmarks, const std::vector<CompressionCase>& cases,
                                                              const PredictionOptions& options, std::vector<std::vector<double>>* warm)
{
    if (warm && warm->size() != cases.size()) fail("evaluate cases: {} warm starts for {} cases", warm->size(), cases.size());
    std::vector<std::pair<std::string, TreReport>> out(cases.size());
    std::vector<std::string> errors(cases.size());
    // One case per thread, each solver single-threaded; the cases left after the last whole round
    // one after another on the full team.
    for_each_task_packed(cases.size(), [&](std::size_t c) {
        try {
            PredictionOptions start = options;
            if (warm) start.initial_displacement_mm = (*warm)[c];
            auto prediction = predict_compression(model, cases[c].tool, rest_landmarks, start, "compression " + cases[c].name);
            if (warm) (*warm)[c] = std::move(prediction.displacement_mm);
            out[c] = {cases[c].name, compute_tre(prediction.landmarks, cases[c].truth, "compression " + cases[c].name)};
        } catch (const std::exception& e) {
            errors[c] = e.what();
        }
    });
    for (const auto& e : errors)
        if (!e.empty()) fail("{} (model parameters: {} {}, k_c,s-t {:.4g} N/m, k_c,s-v {:.4g} N/m, E tumour {:.4g} Pa, E vessel {:.4g} Pa, E body {:.4g} Pa)",
                             e, to_string(parameters.region), to_string(parameters.variant), parameters.coupling.parenchyma_tumour_n_per_m,
                             parameters.coupling.parenchyma_vessel_n_per_m, parameters.tumour_young_pa, parameters.vessel_young_pa,
                             parameters.body_young_pa);
    return out;
}

namespace {

/// A parameter the estimation moves (as its log10), with its slot in the model parameters and bounds.
struct FreeParameter {
    const char* name;
    double* (*slot)(ModelParameters&);
    double lo, hi;
};

/// The free parameters the options and the model variant call for.
std::vector<FreeParameter> free_parameters(const ModelParameters& initial, const EstimationOptions& options)
{
    std::vector<FreeParameter> free;
    const bool coupled = initial.variant == ModelVariant::coupled;
    if (coupled && options.fit_coupling) {
        free.push_back({"k_c_s_t_n_per_m", [](ModelParameters& p) { return &p.coupling.parenchyma_tumour_n_per_m; }, options.k_min_n_per_m, options.k_max_n_per_m});
        free.push_back({"k_c_s_v_n_per_m", [](ModelParameters& p) { return &p.coupling.parenchyma_vessel_n_per_m; }, options.k_min_n_per_m, options.k_max_n_per_m});
    }
    if (options.fit_moduli && initial.variant != ModelVariant::homogeneous) {
        free.push_back({"tumour_young_pa", [](ModelParameters& p) { return &p.tumour_young_pa; }, options.modulus_min_pa, options.modulus_max_pa});
        free.push_back({"vessel_young_pa", [](ModelParameters& p) { return &p.vessel_young_pa; }, options.modulus_min_pa, options.modulus_max_pa});
    }
    if (options.fit_body_modulus && initial.region == ModelRegion::body)
        free.push_back({"body_young_pa", [](ModelParameters& p) { return &p.body_young_pa; }, options.body_modulus_min_pa, options.body_modulus_max_pa});
    return free;
}

/// NLopt (BOBYQA or Nelder–Mead) over the free parameters' log10 values from x; x and best are the
/// best point seen and its value; the optimiser's name and stop reason go into result. An error
/// inside the objective stops the run and is re-raised.
void minimise_with_nlopt(const std::function<double(const std::vector<double>&)>& objective, const std::vector<FreeParameter>& free,
                         const EstimationOptions& options, std::vector<double>& x, double& best, EstimationResult& result)
{
    std::string failure;
    const auto algorithm = options.algorithm == "bobyqa" ? nlopt::LN_BOBYQA : nlopt::LN_NELDERMEAD;
    nlopt::opt opt(algorithm, static_cast<unsigned>(free.size()));
    std::vector<double> lo, hi, step;
    for (const auto& f : free) lo.push_back(std::log10(f.lo)), hi.push_back(std::log10(f.hi)), step.push_back(0.5);
    opt.set_lower_bounds(lo);
    opt.set_upper_bounds(hi);
    opt.set_initial_step(step);
    opt.set_xtol_abs(options.x_tolerance_decades);
    opt.set_maxeval(options.max_evaluations);
    struct Context {
        const std::function<double(const std::vector<double>&)>* f;
        std::string* failure;
        nlopt::opt* opt;
    } context{&objective, &failure, &opt};
    opt.set_min_objective(
        [](const std::vector<double>& v, std::vector<double>&, void* data) {
            auto* c = static_cast<Context*>(data);
            try {
                return (*c->f)(v);
            } catch (const std::exception& e) {
                *c->failure = e.what();
                c->opt->force_stop();
                return HUGE_VAL;
            }
        },
        &context);
    nlopt::result code = nlopt::FAILURE;
    try {
        code = opt.optimize(x, best);
    } catch (const nlopt::forced_stop&) {
        code = nlopt::FORCED_STOP;
    } catch (const std::exception& e) {
        if (failure.empty()) fail("estimation: optimiser {} failed: {}", opt.get_algorithm_name(), e.what());
    }
    if (!failure.empty()) fail("estimation stopped: {}", failure);
    result.optimiser = std::string("NLopt ") + (options.algorithm == "bobyqa" ? "LN_BOBYQA" : "LN_NELDERMEAD");
    switch (code) {
    case nlopt::XTOL_REACHED: result.stop_reason = "parameter tolerance reached"; break;
    case nlopt::FTOL_REACHED: result.stop_reason = "objective tolerance reached"; break;
    case nlopt::MAXEVAL_REACHED: result.stop_reason = "evaluation budget used (may not be converged)"; break;
    case nlopt::SUCCESS: result.stop_reason = "converged"; break;
    default: result.stop_reason = fmt::format("NLopt code {}", static_cast<int>(code)); break;
    }
}

/// The objective's change per decade of each parameter, from the evaluations that moved it alone
/// from the start (the optimiser's first steps); infeasible evaluations are left out.
std::vector<EstimationResult::Sensitivity> parameter_profiles(const std::vector<FreeParameter>& free, const std::vector<EstimationStep>& history,
                                                              double infeasible_mm)
{
    std::vector<EstimationResult::Sensitivity> profiles;
    auto log_of = [&](const ModelParameters& p) {
        std::vector<double> v;
        for (const auto& f : free) v.push_back(std::log10(*f.slot(const_cast<ModelParameters&>(p))));
        return v;
    };
    const auto start = log_of(history.front().parameters);
    const double start_value = history.front().objective_mm;
    for (std::size_t i = 0; i < free.size(); ++i) {
        EstimationResult::Sensitivity s{free[i].name, 0.0, 0, false};
        for (const auto& step : history) {
            if (step.objective_mm >= infeasible_mm) continue;
            const auto x = log_of(step.parameters);
            bool alone = std::abs(x[i] - start[i]) > 1e-6;
            for (std::size_t j = 0; j < free.size() && alone; ++j)
                if (j != i && std::abs(x[j] - start[j]) > 1e-9) alone = false;
            if (!alone) continue;
            s.mm_per_decade = std::max(s.mm_per_decade, std::abs(step.objective_mm - start_value) / std::abs(x[i] - start[i]));
            ++s.evaluations;
        }
        s.identifiable = s.evaluations > 0 && s.mm_per_decade >= EstimationResult::identifiable_mm_per_decade;
        profiles.push_back(s);
    }
    return profiles;
}

} // namespace

EstimationResult estimate_parameters(const LabelVolume& rest_labels, const LabelRoles& roles, const ModelParameters& initial,
                                     const LandmarkSet& rest_landmarks, const std::vector<CompressionCase>& train,
                                     const std::vector<CompressionCase>& validation, const EstimationOptions& options,
                                     const std::function<void(double, const std::string&)>& progress)
{
    options.validate();
    initial.validate();
    if (train.empty()) fail("estimation: no training compression");
    if (rest_landmarks.empty()) fail("estimation: the rest state has no landmarks");
    for (const auto& c : train)
        if (c.truth.empty()) fail("estimation: training compression {} has no landmarks", c.name);
    const auto t0 = std::chrono::steady_clock::now();
    EstimationResult result;
    result.fingerprint = build_liver_model(rest_labels, roles, initial, "rest labels").fingerprint;
    const std::vector<FreeParameter> free = free_parameters(initial, options);
    for (const auto& f : free) result.free_parameters.push_back(f.name);
    auto parameters_at = [&](const std::vector<double>& x) {
        ModelParameters p = initial;
        for (std::size_t i = 0; i < free.size(); ++i) *free[i].slot(p) = std::pow(10.0, x[i]);
        return p;
    };
    const int budget = free.empty() ? 1 : options.max_evaluations;
    constexpr double infeasible_mm = 1e3;
    // Each evaluation starts from the previous one's equilibria: nearby parameters move the
    // tissue little, so relaxation needs a fraction of the iterations from rest.
    std::vector<std::vector<double>> warm(train.size());
    double best_value = 0.0;
    std::vector<std::pair<std::string, TreReport>> best_reports;
    std::vector<std::vector<double>> best_warm;
    auto objective = [&](const std::vector<double>& x) {
        const ModelParameters p = parameters_at(x);
        std::vector<std::pair<std::string, TreReport>> reports;
        try {
            reports = evaluate_cases(rest_labels, roles, p, rest_landmarks, train, options.prediction, &warm);
        } catch (const Error& e) {
            // Parameters under which the model folds an element are infeasible, not a failed
            // estimation: a penalty far above any TRE steers the optimiser away. The start point
            // (the first evaluation) must be feasible.
            if (result.history.empty() || std::string(e.what()).find("inverted") == std::string::npos) throw;
            logger()->warn("estimation: evaluation {} folds an element; treated as infeasible: {}", result.history.size() + 1, e.what());
            result.history.push_back({p, infeasible_mm});
            ++result.infeasible_evaluations;
            return infeasible_mm;
        }
        std::vector<TreReport> pooled;
        for (const auto& r : reports) pooled.push_back(r.second);
        const double value = pool_tre(pooled).all.mean_mm;
        if (result.history.empty() || value < best_value) best_value = value, best_reports = reports, best_warm = warm;
        result.history.push_back({p, value});
        if (progress)
            progress(std::min(1.0, double(result.history.size()) / double(budget)),
                     fmt::format("evaluation {}: k_s-t {:.4g} N/m, k_s-v {:.4g} N/m, E_t {:.3g} Pa, E_v {:.3g} Pa, E_body {:.3g} Pa → mean TRE {:.4f} mm",
                                 result.history.size(), p.coupling.parenchyma_tumour_n_per_m, p.coupling.parenchyma_vessel_n_per_m,
                                 p.tumour_young_pa, p.vessel_young_pa, p.body_young_pa, value));
        return value;
    };
    std::vector<double> x;
    for (const auto& f : free) x.push_back(std::log10(std::clamp(*f.slot(const_cast<ModelParameters&>(initial)), f.lo, f.hi)));
    if (free.empty()) {
        result.optimiser = "none (no free parameter: the model is evaluated)";
        result.stop_reason = "nothing to fit";
        result.objective_mm = objective(x);
        result.fitted = initial;
    } else {
        double best = 0.0;
        minimise_with_nlopt(objective, free, options, x, best, result);
        // The best point NLopt saw (it returns it in x).
        result.fitted = parameters_at(x);
        result.objective_mm = best;
        for (std::size_t i = 0; i < free.size(); ++i)
            if (x[i] - std::log10(free[i].lo) < 0.05 || std::log10(free[i].hi) - x[i] < 0.05) {
                result.at_bound.push_back(free[i].name);
                logger()->warn("estimation: {} = {:.4g} ends at its bound [{:.4g}, {:.4g}]: the optimum may lie beyond it", free[i].name,
                               std::pow(10.0, x[i]), free[i].lo, free[i].hi);
            }
    }
    // One-parameter steps from the start: a profile of each parameter around it.
    if (!result.history.empty() && !free.empty()) result.sensitivity = parameter_profiles(free, result.history, infeasible_mm);
    // The training reports of the best evaluation (NLopt returns the best point it evaluated).
    if (best_value == result.objective_mm) {
        result.train = best_reports;
        result.train_displacement_mm = std::move(best_warm);
    } else {
        result.train_displacement_mm.assign(train.size(), {});
        result.train = evaluate_cases(rest_labels, roles, result.fitted, rest_landmarks, train, options.prediction, &result.train_displacement_mm);
    }
    if (!validation.empty()) result.validation = evaluate_cases(rest_labels, roles, result.fitted, rest_landmarks, validation, options.prediction);
    std::vector<TreReport> t, v;
    for (const auto& r : result.train) t.push_back(r.second);
    for (const auto& r : result.validation) v.push_back(r.second);
    result.train_pooled = pool_tre(t);
    if (!v.empty()) result.validation_pooled = pool_tre(v);
    auto at_rest = [&](const std::vector<CompressionCase>& cases) {
        std::vector<TreReport> reports;
        for (const auto& c : cases) reports.push_back(compute_tre(rest_landmarks, c.truth, "compression " + c.name + " (at rest)"));
        return pool_tre(reports);
    };
    result.train_at_rest = at_rest(train);
    if (!validation.empty()) result.validation_at_rest = at_rest(validation);
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return result;
}

} // namespace physreg
