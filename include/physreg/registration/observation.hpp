// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// What is seen during the operation, whichever model it drives (issue 29): the tracked tool's
// poses, a point cloud of a surface, or a new segmentation. register_model() picks the mode and
// the solver that observation needs and returns the model's nodal displacement:
//   ToolObservation         → compression/  TLED Neo-Hookean to equilibrium (paper 000)
//   CloudObservation        → surface/      co-rotational backward Euler under pair forces (paper 001)
//   SegmentationObservation → images/       linear elasticity, adjoint L-BFGS (paper 002)
#include "physreg/image/image_geometry.hpp"
#include "physreg/io/point_cloud.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/registration/compression/liver_model.hpp"
#include "physreg/registration/images/segmentation_registration.hpp"
#include "physreg/registration/model.hpp"
#include "physreg/registration/surface/surface_registration.hpp"

#include <functional>
#include <string>
#include <variant>
#include <vector>

namespace physreg {

/// The tool moved from its first contact (path.front()) to its last pose (path.back()). A single
/// tracked pose is an observation too: see with_approach_path.
struct ToolObservation {
    Indenter tool;
};
/// A surface seen by a scanner or a tracked pointer: points (mm, LPS), regions, optional normals.
struct CloudObservation {
    LabelledPointCloud cloud;
};
/// A new segmentation of the same structures (labels as in the model's cells).
struct SegmentationObservation {
    LabelVolume labels;
};
using Observation = std::variant<ToolObservation, CloudObservation, SegmentationObservation>;

/// Each mode's settings; register_model reads the one its observation needs.
struct ModelRegistrationSettings {
    PredictionOptions compression;
    CloudRegistrationSettings cloud;
    SegmentationRegistrationOptions segmentation;
};

struct ModelRegistration {
    std::string mode;                        ///< compression, surface, images
    std::string solver;                      ///< in words
    std::vector<double> displacement_mm;     ///< 3 per model node
    std::string notes;                       ///< what the mode decided on the way (images: the rigid pre-fit)
    double seconds = 0.0;
};

/// Registers `model` to `observation` with that observation's mode. Throws Error naming the mode
/// and the reason when the model does not suit it (e.g. a tool on tetrahedra, a segmentation of a
/// model with coupled tissues).
ModelRegistration register_model(const Model& model, const Observation& observation, const ModelRegistrationSettings& settings = {},
                                 const std::function<void(double, const std::string&)>& progress = {});

/// A one-pose sphere's path: in along the outward normal of the model's surface point nearest the
/// pose, from where the sphere first touched it (a pose clear of the surface stays put). Paths of
/// two or more poses are returned as they are. Throws Error for another shape or a model without surface.
Indenter with_approach_path(const Model& model, Indenter tool);

/// Rest points carried by a model's nodal displacement (interpolated in the cell that holds each
/// point). Throws Error naming `what` for a point farther than `max_distance_mm` from the mesh.
std::vector<Vec3> displace_points(const Model& model, const std::vector<double>& displacement_mm, const std::vector<Vec3>& points,
                                  double max_distance_mm, const std::string& what);

} // namespace physreg
