// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/evaluation/predicted_error.hpp"

#include "physreg/core/error.hpp"

#include <fmt/format.h>

#include <cmath>

namespace physreg {

namespace {

// scripts/calibrate_predicted_error.py fit, over scripts/study_adjoint_liver.py's 45 frames x 3 rows
// (2026-12-06): k is the geometric mean of TRE / s, the interval the 10th and 90th percentiles of
// TRE / (k s). The free log-log slope was 0.94 (springs) and 1.01 (held), hence a plain factor.
// The springs row was fitted again once the springs were graded by the distance to the cloud
// (2026-12-06, the 45 default runs again: slope 1.07), and both once more when the parenchyma's
// default ν became 0.48 (the same 135 runs re-run: slopes 1.03 and 0.96; the held answers err
// less for the same energy, factor 0.104 -> 0.0765).
struct Calibration {
    double factor, low, high;
};
constexpr Calibration springs_calibration{0.2476, 0.718, 1.617}; // 45 runs, Spearman 0.64
constexpr Calibration held_calibration{0.0765, 0.505, 1.838};    // 90 runs, Spearman 0.82
constexpr double stated_coverage = 0.8;

void require(bool ok, const std::string& parameter, double value, const char* rule)
{
    if (!ok) throw Error(fmt::format("predicted error: {} = {} must be {}", parameter, value, rule));
}

} // namespace

PredictedError predict_error_from_strain_energy(double strain_energy_mj, double young_modulus_pa, double volume_mm3, SupportRegime regime)
{
    require(std::isfinite(strain_energy_mj) && strain_energy_mj >= 0.0, "strain energy (mJ)", strain_energy_mj, "finite and >= 0");
    require(std::isfinite(young_modulus_pa) && young_modulus_pa > 0.0, "Young's modulus (Pa)", young_modulus_pa, "finite and > 0");
    require(std::isfinite(volume_mm3) && volume_mm3 > 0.0, "model volume (mm^3)", volume_mm3, "finite and > 0");
    const Calibration& c = regime == SupportRegime::springs ? springs_calibration : held_calibration;
    PredictedError p;
    p.regime = regime;
    // mJ / (Pa mm^3) = 1e-3 J / 1e-9 J: the strain is dimensionless once the 1e6 is applied.
    const double strain = std::sqrt(2.0 * strain_energy_mj * 1e6 / (young_modulus_pa * volume_mm3));
    p.energy_scale_mm = std::cbrt(volume_mm3) * strain;
    p.mean_mm = c.factor * p.energy_scale_mm;
    p.low_mm = c.low * p.mean_mm;
    p.high_mm = c.high * p.mean_mm;
    p.interval_coverage = stated_coverage;
    return p;
}

nlohmann::json to_json(const PredictedError& p)
{
    const bool springs = p.regime == SupportRegime::springs;
    return {{"mean_mm", p.mean_mm},
            {"interval_mm", {p.low_mm, p.high_mm}},
            {"interval_coverage", p.interval_coverage},
            {"energy_scale_mm", p.energy_scale_mm},
            {"regime", springs ? "springs" : "held"},
            {"rule", fmt::format("mean interior error = {:.3f} x L sqrt(2U/(E V)), L = V^(1/3), U the answer's strain energy "
                                 "(Heiselman & Miga 2021); the interval held {:.0f} % of the calibration runs",
                                 springs ? springs_calibration.factor : held_calibration.factor, 100.0 * p.interval_coverage)},
            {"calibration", "the public optimal-control liver (Mestdagh & Cotin 2022), 45 frames x 3 rows; "
                            "scripts/calibrate_predicted_error.py"},
            {"valid_when", "the cloud sees the region that moved (a push under a 500-point cloud): it measures the motion the answer "
                           "made, not motion the cloud missed; on small patches of the project's phantom it predicted far too little "
                           "(Spearman 0.18, median 0.0x the true error)"},
            {"statement", fmt::format("predicted mean error at interior targets {:.1f} mm ({:.0f} % interval {:.1f}-{:.1f} mm), "
                                      "from the strain energy the answer needs", p.mean_mm, 100.0 * p.interval_coverage, p.low_mm, p.high_mm)}};
}

} // namespace physreg
