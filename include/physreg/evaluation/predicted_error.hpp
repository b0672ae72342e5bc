// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// A registration's error predicted from the strain energy its answer needs (Heiselman & Miga 2021:
// the energy a fit costs ranks its target error). The displacement scale that energy implies is
//   s = L sqrt(2 U / (E V)),   L = V^(1/3)   [mm],
// and the mean interior error is taken as k s, one factor k per support regime, with an 80 %
// interval. k and the interval were calibrated on the public optimal-control liver
// (scripts/calibrate_predicted_error.py over scripts/study_adjoint_liver.py's 135 runs) and checked on
// frames the calibration never saw (docs/validation/adjoint_liver.md).

#include <nlohmann/json.hpp>

#include <string>

namespace physreg {

enum class SupportRegime {
    springs, ///< nothing names the supports: soft springs to rest at every node
    held,    ///< supports named by the user or chosen among hypotheses
};

struct PredictedError {
    double energy_scale_mm = 0.0;    ///< s above
    double mean_mm = 0.0;            ///< predicted mean error at interior targets
    double low_mm = 0.0, high_mm = 0.0; ///< the stated interval
    double interval_coverage = 0.0;  ///< the fraction of calibration runs the interval held
    SupportRegime regime = SupportRegime::springs;
};

/// strain_energy_mj >= 0 and finite, young_modulus_pa > 0, volume_mm3 > 0; otherwise an Error naming
/// the parameter.
PredictedError predict_error_from_strain_energy(double strain_energy_mj, double young_modulus_pa, double volume_mm3, SupportRegime regime);

/// For summary.json: the figures, the regime, the rule and where it was calibrated.
nlohmann::json to_json(const PredictedError& p);

} // namespace physreg
