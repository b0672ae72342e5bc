#include "physreg/mechanics/material.hpp"

#include "physreg/core/error.hpp"

namespace physreg {

MaterialLaw parse_material_law(const std::string& text)
{
    if (text == "neo-hookean" || text == "neo_hookean") return MaterialLaw::neo_hookean;
    if (text == "svk" || text == "st-venant-kirchhoff") return MaterialLaw::st_venant_kirchhoff;
    if (text == "linear" || text == "linear-elastic") return MaterialLaw::linear_elastic;
    fail("material law '{}' is not one of neo-hookean, svk, linear", text);
}

std::string to_string(MaterialLaw law)
{
    switch (law) {
    case MaterialLaw::neo_hookean: return "neo-hookean";
    case MaterialLaw::st_venant_kirchhoff: return "svk";
    default: return "linear";
    }
}

ElasticMaterial material_from_tissue(const Tissue& t)
{
    TissueTable single;
    single.tissues = {t};
    single.validate("material");
    const double e = t.young_modulus_pa * 1e-6; // Pa → MPa
    const double nu = t.poisson_ratio;
    ElasticMaterial m;
    m.mu_mpa = e / (2.0 * (1.0 + nu));
    m.lambda_mpa = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    m.kappa_mpa = e / (3.0 * (1.0 - 2.0 * nu));
    m.density_t_mm3 = t.density_kg_m3 * 1e-12; // kg/m³ → t/mm³
    return m;
}

} // namespace physreg
