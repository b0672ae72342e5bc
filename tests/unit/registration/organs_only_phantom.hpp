// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The `small` phantom with the organs-only ground truth (no gel; the tool presses the liver, depths
// 6–8 mm from the organ surface, a 12 mm ball): the registration models' own mechanics are tested
// on it, since through the gel their tool would barely reach the liver.
#include "physreg/phantom/dataset.hpp"

namespace physreg::test {

inline PhantomSpec organs_only_small_spec()
{
    PhantomSpec spec = PhantomSpec::preset_spec("small");
    spec.simulate_body = false;
    spec.depths_mm = {6, 8, 6, 5, 6};
    spec.tool.radius_mm = 12.0;
    spec.load_step_mm = 3.0;
    spec.calculix_validation = false;
    return spec;
}

} // namespace physreg::test
