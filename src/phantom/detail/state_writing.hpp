// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// Writing the phantom's states: each state's folder (labels and MR-like intensity warped by the
// ground truth, forward and inverse fields, the mesh, landmarks exact and noisy, partial surfaces or
// the push's sparse cloud, a picture) and its manifest entry.
#include "phantom_states.hpp"

#include "physreg/core/landmark.hpp"
#include "physreg/image/image_geometry.hpp"
#include "physreg/mesh/labelled_boundary.hpp"
#include "physreg/mesh/point_location.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace physreg::detail {

nlohmann::json to_json(const Vec3& v);
std::string shape_name(IndenterShape s);
LandmarkSet move_landmarks(const LandmarkSet& rest, const std::vector<NodeEmbedding>& where, const VolumeMesh& mesh, const std::vector<double>& u);
LandmarkSet with_noise(const LandmarkSet& set, double sigma, std::uint64_t seed);
/// Paints the tool and its shaft (the tool swept back along the pressing direction) as air.
void paint_tool(LabelVolume& labels, ScalarImage& intensity, const Indenter& tool, const Vec3& direction,
                const std::function<bool(std::int32_t)>& deforming);
void write_text(const std::filesystem::path& path, const std::string& text);

/// Writes root/relative by `write` (its folders made first) and returns `relative` for the manifest.
template <typename Write>
std::string write_file(const std::filesystem::path& root, const std::string& relative, Write write)
{
    std::filesystem::create_directories((root / relative).parent_path());
    write(root / relative);
    return relative;
}

/// A ground-truth model as the states see it: where the landmarks sit, and the liver's labelled boundary.
struct ModelView {
    const GroundTruthModel* model;
    std::vector<NodeEmbedding> landmark_cells;
    BoundarySurface liver_surface;
};

class StateWriter {
public:
    StateWriter(const std::filesystem::path& root, const PhantomSpec& spec, const Prepared& p, const ScalarImage& intensity,
                const LandmarkSet& rest_landmarks, const Vec3& liver_centre);
    /// Writes the state `name` (rest: `solved` null) of `view`'s model and returns its manifest entry;
    /// `report(fraction, message)` hears when its images are being made.
    nlohmann::json write(const std::string& name, const std::string& kind, const SolvedState* solved, const ModelView& view, double f0,
                         const std::function<void(double, const std::string&)>& report) const;

private:
    std::filesystem::path m_root;
    const PhantomSpec& m_spec;
    const Prepared& m_p;
    const ScalarImage& m_intensity;
    const LandmarkSet& m_rest_landmarks;
    Vec3 m_liver_centre;
    double m_fill_intensity = 0.0, m_air_intensity = 0.0; ///< mean intensity of the gel and of the air
    std::uint16_t m_body_label = 0;
    double m_extension_mm = 0.0; ///< how far the inverse map reaches beyond the mesh
};

} // namespace physreg::detail
