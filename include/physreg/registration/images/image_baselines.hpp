// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The image-registration baselines paper 002 compares with, all from ITK, run on the same pair:
// - rigid: VersorRigid3DTransform, ImageRegistrationMethodv4, Mattes mutual information
//   (intensity) or mean squares (labels), regular-step gradient descent, 3 levels (shrink 4/2/1).
// - demons: DiffeomorphicDemonsRegistrationFilter in a 3-level MultiResolutionPDEDeformable-
//   Registration (intensities histogram-matched first), Gaussian field regularisation.
// - bspline: cubic BSplineTransform, mean squares minimised by ITK's L-BFGS-B, 3 levels (image
//   smoothing σ 2/1/0 voxels) with the control grid refined ×2 per level (BSplineTransform-
//   ParametersAdaptor); the mean squares and its sparse gradient are ours (ITK 5.2's metrics are
//   dense in the parameters, and its sparse Mattes metric drifted on identical images).
//   No bending-energy penalty: inside a uniform structure the control points see no data.
// Each runs on the intensities or on the label maps (labels turned into a smooth image: each
// structure a distinct grey value, Gaussian σ = 1 voxel), so every report compares both.
// The result is a dense field on the fixed grid in ITK's convention: the fixed point x maps to the
// moving point x + d(x) — what resampling the moving image needs.
#include "physreg/image/image_geometry.hpp"

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace physreg {

enum class BaselineMethod { rigid, demons, bspline };
BaselineMethod parse_baseline_method(const std::string& text); ///< rigid | demons | bspline
std::string to_string(BaselineMethod method);

struct BaselineOptions {
    int rigid_iterations = 200;                      ///< per level
    std::vector<int> demons_iterations{60, 40, 20}; ///< coarse → fine
    double demons_field_sigma_voxels = 1.5;          ///< Gaussian regularisation of the field
    double bspline_grid_mm = 50.0;                   ///< control-point spacing at the coarsest level (halved per level)
    int bspline_iterations = 100;                    ///< per level
    double bspline_sampling = 0.2;                   ///< fraction of fixed voxels sampled by the metric
    unsigned seed = 1;
    void validate() const;
};

struct BaselineResult {
    DisplacementField fixed_to_moving;      ///< d(x) in mm on the fixed grid
    double seconds = 0.0;
    std::map<std::string, double> figures;  ///< metric value, iterations, rotation, …
};

/// Registers `moving` onto `fixed` (any grids for rigid and B-spline, one grid for Demons; physical
/// LPS space). `labels_mode`: the inputs are label-derived images (mean squares for the rigid
/// method, no histogram matching for Demons). Throws Error when
/// the images do not overlap or ITK fails (its message included).
BaselineResult register_baseline(const ScalarImage& fixed, const ScalarImage& moving, BaselineMethod method, bool labels_mode,
                                 const BaselineOptions& options);

/// The label image as a smooth grey-value image for intensity-based registration: the structures
/// in `structures` get values 100, 200, … (in order), others 0; Gaussian σ = 1 voxel.
ScalarImage label_intensity_image(const LabelVolume& labels, const std::vector<std::int32_t>& structures);

} // namespace physreg
