// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// `physreg phantom`: an experiment dataset built from the built-in CIRS-057A-like phantom or any
// label map — the shared test bed of every registration method in physreg. From the rest labels it
// makes an MR-like image, 25 landmarks, tool compressions A–E and an insufflation-like pressure,
// each solved to equilibrium on a finer ground-truth model (tissues sharing nodes, TLED
// Neo-Hookean, indenter contact), with deformed images, ITK displacement fields, VTU meshes,
// partial intra-operative surfaces, segmentation pairs, pictures and a JSON manifest.
#include "physreg/core/types.hpp"
#include "physreg/model/loads.hpp"
#include "physreg/mechanics/explicit/tled_solver.hpp"
#include "physreg/model/tissue_table.hpp"
#include "physreg/phantom/abdominal_phantom.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/phantom/ground_truth.hpp"

#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace physreg {

/// paper000: parenchyma 2e5, vessel 1e6, lesion 5e6 Pa, ν 0.49. healthy / cirrhotic (paper 001):
/// parenchyma 3.5 kPa / 30 kPa, ν 0.45; vessels 620 kPa, ν 0.4; lesions 10× the parenchyma (our
/// assumption: paper 001 has none). Kidneys (our assumption): 2.5× the parenchyma, same ν.
enum class MaterialSet { paper000, healthy, cirrhotic };
MaterialSet parse_material_set(const std::string& text);
std::string to_string(MaterialSet set);
/// The mechanical model's tissues: every liver role label and the kidneys present in `labels`;
/// every other label is ignored (not meshed). Names: parenchyma, lesion, vessel, kidney.
TissueTable phantom_tissue_table(MaterialSet set, const LabelRoles& roles, const std::set<std::int32_t>& present_labels);

struct ToolSpec {
    IndenterShape shape = IndenterShape::sphere; ///< sphere, cylinder (a rod pressed sideways) or box
    double radius_mm = 12.5;                     ///< sphere, cylinder
    Vec3 axis = Vec3::UnitX();                   ///< cylinder axis (⟂ to the pressing direction)
    Vec3 half_extents_mm = Vec3(12, 6, 12);      ///< box, in LPS axes
};

struct CompressionSpec {
    std::string name;
    double x_mm = 0.0, z_mm = 0.0;       ///< where the tool enters: the line x = x_mm, z = z_mm (LPS)
    Vec3 direction = Vec3::UnitY();      ///< pressing direction (default posterior, +y)
    double depth_mm = 10.0;              ///< travel beyond first contact with an organ
    ToolSpec tool;
};

struct PhantomSpec {
    std::string preset = "cirs057a";          ///< cirs057a, small (tests) or from-labels
    std::filesystem::path labels_file;        ///< from-labels: the label map
    LabelRoles roles = phantom_label_roles(); ///< from-labels: which label is which organ
    std::filesystem::path vessel_mask;        ///< optional: nonzero voxels inside the liver become vessel
    double voxel_mm = 1.0;                    ///< preset image resolution
    /// Seed of everything random: anatomy noise, ground-truth materials, mesh, landmark and surface
    /// noise. 1 … 4294967295 (CGAL's generator takes 32 bits).
    std::uint64_t seed = 1;
    /// The literature values the ground-truth moduli are drawn around (ground_truth.hpp).
    MaterialSet materials = MaterialSet::paper000;
    GroundTruthMeshing ground_truth_mesh;
    /// false: the organs alone, posterior faces fixed, the tool pressing the organs directly (no gel)
    /// — the pre-issue-17 setting, for studies of the liver models' own mechanics (and their tests).
    bool simulate_body = true;
    /// Where the organs alone are held (the insufflation, the push and --organs-only states).
    OrganSupport organ_support;
    double load_step_mm = 5.0;                ///< largest tool travel per Newton load step
    /// Run the small CalculiX validation of the ground-truth discretisation (needs ccx; the
    /// manifest says so when it is absent).
    bool calculix_validation = true;
    /// Five positions over the liver when empty; depths (mm, travel on the skin from first contact)
    /// used for them, in order A, B, ….
    std::vector<CompressionSpec> compressions;
    std::vector<double> depths_mm{20, 25, 20, 15, 22};
    ToolSpec tool;
    std::optional<double> insufflation_pa;    ///< default: 3 % of the parenchyma's Young's modulus; 0 disables
    /// The large local push (issue 32): a sphere of `push_tool_radius_mm` pressed `push_depth_mm`
    /// (posterior) into one lobe of the organs-alone model (held where the insufflation's is), seen
    /// as a sparse cloud of `push_cloud_points` unlabelled points over the surface outside the tool
    /// and the posterior `1 − push_cloud_coverage` of it. 0: no push state (the default).
    double push_depth_mm = 0.0;
    double push_tool_radius_mm = 12.5;
    int push_cloud_points = 500;
    double push_cloud_coverage = 0.9;
    double landmark_noise_mm = 0.5;
    double surface_noise_mm = 0.5;
    std::vector<int> surface_percentages{50, 40, 30, 20, 10};
    /// The named preset: "cirs057a" (the default) or "small" (4 mm voxels, a coarse ground truth
    /// and shallower compressions; for tests). Throws Error for an unknown name.
    static PhantomSpec preset_spec(const std::string& name);
    void validate() const;
};

/// Figures of a finished run, for the caller's report (no timings are written into the dataset
/// itself, so the same seed gives identical files).
struct DatasetReport {
    std::string summary_json;                      ///< the manifest plus run times
};

/// Builds the dataset into `directory` (staged: it appears only when complete; an existing
/// non-empty folder is refused unless `replace`). `progress(fraction, message)` along the way: one call at a time, but possibly from a worker thread (as each parallel compression solve ends).
DatasetReport generate_phantom_dataset(const PhantomSpec& spec, const std::filesystem::path& directory, bool replace,
                                       const std::function<void(double, const std::string&)>& progress);

} // namespace physreg
