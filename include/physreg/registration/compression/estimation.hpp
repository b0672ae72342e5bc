// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 000 eqs. 6–7: the model parameters (coupling stiffnesses k_{c,s-t}, k_{c,s-v}, optionally
// the tumour and vessel Young's moduli) that minimise the mean landmark error over training
// compressions, found by a derivative-free optimiser (NLopt's BOBYQA or Nelder–Mead) on
// log10-scaled parameters within bounds. Training compressions are solved in parallel.
#include "physreg/evaluation/tre.hpp"
#include "physreg/registration/compression/liver_model.hpp"

#include <functional>

namespace physreg {

/// A compression with its ground truth: the tool's path and the landmarks it produced.
struct CompressionCase {
    std::string name;
    Indenter tool;
    LandmarkSet truth;
};

/// The named compressions of a phantom dataset (`physreg phantom`) with their ground-truth
/// landmarks. Throws Error for an unknown state, a state that is not a tool compression, or one
/// without landmarks.
struct PhantomDataset;
std::vector<CompressionCase> compression_cases(const PhantomDataset& dataset, const std::vector<std::string>& names);

struct EstimationOptions {
    bool fit_coupling = true;                ///< coupled variant: k_{c,s-t}, k_{c,s-v}
    bool fit_moduli = false;                 ///< tumour and vessel E (parenchyma's fixes the scale)
    /// Body region: the gel's E (the gel-to-parenchyma ratio: the tool presses the gel, which
    /// carries the load to the liver; the parenchyma's E fixes the scale).
    bool fit_body_modulus = true;
    double k_min_n_per_m = 1.0, k_max_n_per_m = 1e5;
    double modulus_min_pa = 1e4, modulus_max_pa = 1e8;
    double body_modulus_min_pa = 2e3, body_modulus_max_pa = 2e6;
    std::string algorithm = "bobyqa";        ///< bobyqa | neldermead
    int max_evaluations = 30;
    double x_tolerance_decades = 0.02;       ///< stop when a step changes log10(parameter) by less
    PredictionOptions prediction;
    void validate() const;
};

struct EstimationStep {
    ModelParameters parameters;
    double objective_mm = 0.0;               ///< mean TRE over the training landmarks
};

struct EstimationResult {
    ModelParameters fitted;
    std::string fingerprint;                 ///< of the model's rest mesh
    double objective_mm = 0.0;
    std::vector<EstimationStep> history;
    std::vector<std::pair<std::string, TreReport>> train, validation; ///< per compression, at the fit
    /// The training compressions' equilibria at the fit (3 per node, mm; in `train`'s order): warm
    /// starts for other models on the same mesh.
    std::vector<std::vector<double>> train_displacement_mm;
    TreReport train_pooled, validation_pooled;
    /// Baseline: the landmarks left where they are at rest (how far the compressions moved them).
    TreReport train_at_rest, validation_at_rest;
    double seconds = 0.0;
    std::string optimiser;                   ///< e.g. "NLopt LN_BOBYQA"
    std::string stop_reason;
    std::vector<std::string> free_parameters; ///< names of the fitted parameters, in optimiser order
    /// Fitted parameters within 0.05 decades of a bound: the optimum may lie beyond it.
    std::vector<std::string> at_bound;
    /// Evaluations whose parameters folded an element (objective 1000 mm, kept in `history`).
    int infeasible_evaluations = 0;
    /// Identifiability, from the evaluations that moved one parameter alone away from the start
    /// (BOBYQA's first steps): the largest |Δ objective| per decade of that parameter. Below
    /// `identifiable_mm_per_decade` the landmarks cannot tell its values apart.
    struct Sensitivity {
        std::string parameter;
        double mm_per_decade = 0.0;
        int evaluations = 0;   ///< feasible one-parameter steps it rests on (0: not measured)
        bool identifiable = false;
    };
    std::vector<Sensitivity> sensitivity;
    static constexpr double identifiable_mm_per_decade = 0.02;
};

/// Solves every case with `parameters` (in parallel over cases); TRE per case. `warm` (optional,
/// one entry per case): each case starts from its entry when it is not empty (an equilibrium of
/// the same mesh, e.g. under the previous parameters) and leaves its new equilibrium there.
std::vector<std::pair<std::string, TreReport>> evaluate_cases(const LabelVolume& rest_labels, const LabelRoles& roles,
                                                              const ModelParameters& parameters, const LandmarkSet& rest_landmarks,
                                                              const std::vector<CompressionCase>& cases, const PredictionOptions& options,
                                                              std::vector<std::vector<double>>* warm = nullptr);
/// The same with a model already built (its parameters are named in errors).
std::vector<std::pair<std::string, TreReport>> evaluate_cases(const LiverModel& model, const ModelParameters& parameters,
                                                              const LandmarkSet& rest_landmarks, const std::vector<CompressionCase>& cases,
                                                              const PredictionOptions& options, std::vector<std::vector<double>>* warm = nullptr);

/// Fits the free parameters of `initial` (none for homogeneous / shared-nodes without
/// fit_moduli: then the model is just evaluated). `progress(fraction, message)` after each
/// evaluation. Throws Error for an empty training set, cases without landmarks, bad bounds.
EstimationResult estimate_parameters(const LabelVolume& rest_labels, const LabelRoles& roles, const ModelParameters& initial,
                                     const LandmarkSet& rest_landmarks, const std::vector<CompressionCase>& train,
                                     const std::vector<CompressionCase>& validation, const EstimationOptions& options,
                                     const std::function<void(double, const std::string&)>& progress = {});

} // namespace physreg
