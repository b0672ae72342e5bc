// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The label → tissue table: which label-volume values are which tissue, and its material.
// Units: Young's modulus in Pa, density in kg/m³, Poisson's ratio dimensionless.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace physreg {

struct Tissue {
    std::int32_t label = 0;
    std::string name;
    double young_modulus_pa = 0.0;
    double poisson_ratio = 0.0;
    double density_kg_m3 = 1000.0;
    /// Mooney–Rivlin law only: C01 / (C10 + C01), in [0, 1) (0 = Neo-Hookean).
    double mooney_rivlin_c01_fraction = 0.0;
};

struct TissueTable {
    std::vector<Tissue> tissues;
    /// Labels present in volumes that are deliberately treated as background (not meshed).
    std::set<std::int32_t> ignored_labels;

    const Tissue* find(std::int32_t label) const;
    /// Throws Error naming `what` and the tissue for E ≤ 0, ν ∉ (−1, 0.5), density ≤ 0, NaN,
    /// label 0 (background), duplicate labels or names.
    void validate(const std::string& what) const;
};

/// YAML or JSON (JSON is read as YAML):
///   tissues:
///     - {label: 1, name: parenchyma, young_modulus_pa: 2.0e5, poisson_ratio: 0.49, density_kg_m3: 1000}
///   ignore_labels: [7]
TissueTable read_tissue_table(const std::filesystem::path& path);
void write_tissue_table(const std::filesystem::path& path, const TissueTable& table);

/// Paper 000's phantom materials: parenchyma 2e5 Pa, vessel 1e6 Pa, tumour 5e6 Pa, ν = 0.49,
/// labels 1, 2, 3.
TissueTable default_tissue_table();

} // namespace physreg
