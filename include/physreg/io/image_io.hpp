// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Medical images through ITK: NIfTI (.nii, .nii.gz), NRRD (.nrrd, .nhdr), MetaImage (.mha, .mhd),
// and DICOM series (pass the directory). Geometry is kept in ITK's physical LPS space, mm.
#include "physreg/image/image_geometry.hpp"

#include <filesystem>
#include <string>

namespace physreg {

struct ImageFileInfo {
    ImageGeometry geometry;
    int dimensions = 0;
    int components = 0;          ///< 1 for scalar images, 3 for displacement fields
    std::string component_type;  ///< e.g. "unsigned_char", "float"
    std::string format;          ///< the ITK ImageIO that read it
};

/// Header only: geometry, pixel type and format. Throws Error for unreadable or non-3-D files.
ImageFileInfo read_image_info(const std::filesystem::path& path);

/// Integer labels 0..65535; a floating-point file must hold integral values. Throws Error naming
/// the file for a missing/corrupt/truncated file, a non-3-D image, a multi-component image,
/// negative, fractional or NaN labels.
LabelVolume read_label_volume(const std::filesystem::path& path);
ScalarImage read_scalar_image(const std::filesystem::path& path);
DisplacementField read_displacement_field(const std::filesystem::path& path);

/// Writers go through a temporary file and a rename: no partial output on failure.
void write_label_volume(const std::filesystem::path& path, const LabelVolume& volume);
void write_scalar_image(const std::filesystem::path& path, const ScalarImage& image);
/// 3-component float vector image, read by ITK, 3D Slicer (as a grid transform) and ANTs as a
/// displacement-field transform: for .nii/.nii.gz ITK writes NIfTI intent 1007 (vector) with the
/// components in the 5th dimension, as ANTs expects.
void write_displacement_field(const std::filesystem::path& path, const DisplacementField& field);

} // namespace physreg
