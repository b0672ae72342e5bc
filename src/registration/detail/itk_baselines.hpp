// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The narrow door to ITK's registration framework (no Eigen here: ITK 5.2 bundles its own).
#include "io/detail/itk_bridge.hpp"

#include <string>
#include <utility>
#include <vector>

namespace physreg::detail {

struct PlainImage {
    PlainGeometry geometry;
    std::vector<float> values;
};

struct PlainBaselineOptions {
    std::string method;         ///< rigid, demons, bspline
    bool labels_mode = false;
    int rigid_iterations = 200;
    std::vector<int> demons_iterations;
    double demons_sigma_voxels = 1.5;
    double bspline_grid_mm = 50.0;
    int bspline_iterations = 100;
    double bspline_sampling = 0.2;
    unsigned seed = 1;
    int threads = 1;
};

struct PlainBaselineResult {
    std::vector<float> field; ///< 3 per fixed voxel: fixed → moving displacement, mm
    std::vector<std::pair<std::string, double>> figures;
};

/// Throws physreg::Error with ITK's message when ITK fails.
PlainBaselineResult itk_register_baseline(const PlainImage& fixed, const PlainImage& moving, const PlainBaselineOptions& options);
/// Recursive Gaussian smoothing, σ in mm.
std::vector<float> itk_smooth(const PlainImage& image, double sigma_mm);

} // namespace physreg::detail
