// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Paper 002's pipeline, whole (issue 43): the one function that `physreg register-images`, Python's
// physreg.register_images and `serve` call. Read top to bottom in image_registration.cpp:
//   1. structures checked in both segmentations;
//   2. initial alignment of the segmentations (identity, centroid, rigid), applied only when it
//      removes enough of the boundary distance;
//   3. the region of interest, conforming tetrahedra of the moving structures, supports;
//   4. the biomechanical registration (linear elasticity, boundary load and moduli by L-BFGS with
//      adjoint gradients; rest offsets), its dense inverse field;
//   5. ITK's rigid, Demons and B-spline baselines on intensities and labels (a failing baseline is a
//      finding, not the end);
//   6. every method composed with the alignment and evaluated (Dice, surface distances, TRE).
// The settings are ImageRegistrationSettings, specified once by image_registration_spec().
#include "physreg/core/settings_spec.hpp"
#include "physreg/core/landmark.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/volume_mesh.hpp"
#include "physreg/model/tissue_table.hpp"
#include "physreg/registration/images/segmentation_alignment.hpp"
#include "physreg/registration/images/segmentation_registration.hpp"

#include <nlohmann/json.hpp>

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace physreg {

/// Every setting of paper 002's pipeline; defaults are the command's (image_registration_spec()
/// holds their ranges and help).
struct ImageRegistrationSettings {
    std::string method = "biomechanical";   ///< the result written: biomechanical, rigid, demons, bspline
    std::string initial = "rigid";          ///< identity, centroid, rigid
    double initial_min_reduction = 0.4;     ///< fraction of the boundary RMS distance the alignment must remove (issue 57: 0.5 → 0.4)
    double initial_max_rotation = 60.0;     ///< degrees: a pose turned farther from the identity must win by a margin the data resolve
    std::string baselines = "all";          ///< all, intensity, labels, none
    std::string hold = "auto";              ///< posterior, none, auto (ImagePair::auto_hold)
    std::vector<std::int32_t> structures;   ///< empty: every label of the moving segmentation
    std::vector<std::int32_t> hold_labels;
    double anchor = 0.0;                    ///< N/mm
    std::string parametrisation = "surface-displacement";
    int iterations = 5;
    int cycles = 40;
    double tolerance = 1e-3;
    double rms_tolerance = 0.001;           ///< mm
    bool estimate_moduli = true;
    double moduli_prior = 0.0;
    double moduli_prior_rms = 0.1;          ///< mm
    std::string law = "linear";             ///< linear, corotational
    bool factor_reuse = true;
    bool rest_offsets = true;
    bool symmetric = false;
    double cell_size = 6.0;                 ///< mm
    double facet_distance = 0.75;           ///< mm
    double margin = 15.0;                   ///< mm
    double bspline_grid = 50.0;             ///< mm
    double demons_sigma = 1.5;              ///< voxels
    int seed = 1;

    /// The solver's options these settings give.
    SegmentationRegistrationOptions solver_options() const;
};

/// The specification of ImageRegistrationSettings: keys, command-line options, ranges, help.
const SettingsSpec<ImageRegistrationSettings>& image_registration_spec();

/// The ranges of the specification and the settings' own rules (a baseline method needs the
/// baselines; a moduli prior needs estimated moduli). Error naming the setting as `naming` says.
void validate(const ImageRegistrationSettings& settings, SettingNaming naming);

/// What paper 002 registers: the moving (pre-operative) image and segmentation, meshed, onto the
/// fixed one; landmarks, when given, measure the TRE.
struct ImagePair {
    ScalarImage fixed, moving;
    LabelVolume fixed_labels, moving_labels;
    /// false: no intensity images were given (a label-to-label pair): fixed and moving are the
    /// label maps as values, the intensity baselines are not run and no warped image is written.
    bool intensities = true;
    std::optional<LandmarkSet> landmarks_fixed, landmarks_moving;
    /// Initial moduli and Poisson ratios per structure; empty: 3 kPa, ν 0.45 for every structure
    /// (only ratios are estimated).
    TissueTable tissues;
    std::string tissues_source;             ///< names the table in errors ("" : none given)
    /// The structures when settings.structures is empty (a dataset's organs); empty: every label of
    /// the moving segmentation, and the fixed one may not have others.
    std::vector<std::int32_t> default_structures;
    std::string auto_hold = "none";         ///< what hold = auto means for this pair
    nlohmann::json description = nlohmann::json::object(); ///< where the pair came from (summary "inputs")
};

/// One method's answer on the region of interest.
struct ImageMethodOutcome {
    std::string name;                       ///< at_rest, initial_alignment, biomechanical, rigid_labels, …
    DisplacementField field;                ///< fixed → moving on the region (the alignment included)
    std::optional<LandmarkSet> landmarks;   ///< the moving landmarks carried onto the fixed image
    LabelVolume warped_labels;              ///< the moving labels through the field
    double seconds = 0.0;
    nlohmann::json details = nlohmann::json::object();
};

struct ImageRegistrationResult {
    ImageRegistrationSettings settings;     ///< as used (hold resolved)
    std::vector<std::int32_t> structures;
    ImageGeometry region;
    SegmentationAlignment alignment;
    bool aligned = false;
    std::string alignment_decision;
    VolumeMesh mesh;                        ///< moving frame, or fixed after the alignment
    SegmentationRegistrationResult biomechanical;
    std::vector<std::uint8_t> held;         ///< per mesh node
    std::vector<ImageMethodOutcome> methods;
    std::map<std::string, std::string> failed_baselines; ///< name → reason
    std::size_t chosen = 0;                 ///< index in methods of settings.method's result
    ScalarImage warped_moving;              ///< the moving image through the chosen field (empty: no intensities)
    nlohmann::json summary, parameters;     ///< summary.json and parameters.json, as written
    const ImageMethodOutcome& chosen_method() const { return methods.at(chosen); }
};

/// Runs the pipeline. `progress(fraction, message)`. Throws Error for bad input (structures
/// missing, images that do not overlap, a singular model) and when the chosen method fails.
ImageRegistrationResult register_images(const ImagePair& pair, const ImageRegistrationSettings& settings,
                                        const std::function<void(double, const std::string&)>& progress = {});

} // namespace physreg
