// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/config_keys.hpp"
#include "physreg/core/error.hpp"
#include "physreg/model/tissue_table.hpp"
#include "test_support.hpp"

#include <fstream>

namespace physreg {
namespace {

std::string error_of(const std::filesystem::path& path)
{
    return test::error_message([&] { read_tissue_table(path); });
}

} // namespace

TEST(ModelTissueTable, ReadsYamlAndJson)
{
    test::TempDir dir;
    std::ofstream(dir / "t.yaml") << "tissues:\n  - {label: 1, name: parenchyma, young_modulus_pa: 2.0e5, poisson_ratio: 0.49}\n"
                                     "  - {label: 3, name: tumour, young_modulus_pa: 5.0e6, poisson_ratio: 0.49, density_kg_m3: 1100}\n"
                                     "ignore_labels: [7]\n";
    const auto t = read_tissue_table(dir / "t.yaml");
    ASSERT_EQ(t.tissues.size(), 2u);
    EXPECT_EQ(t.find(3)->name, "tumour");
    EXPECT_DOUBLE_EQ(t.find(3)->density_kg_m3, 1100);
    EXPECT_DOUBLE_EQ(t.find(1)->density_kg_m3, 1000);
    EXPECT_TRUE(t.ignored_labels.count(7));
    std::ofstream(dir / "t.json") << R"({"tissues": [{"label": 2, "name": "vessel", "young_modulus_pa": 1e6, "poisson_ratio": 0.4}]})";
    EXPECT_DOUBLE_EQ(read_tissue_table(dir / "t.json").find(2)->young_modulus_pa, 1e6);
}

TEST(ModelTissueTable, UnknownKeysAreErrorsWithTheNearestAcceptedKey)
{
    test::TempDir dir;
    std::ofstream(dir / "typo.yaml") << "tissues:\n  - {label: 1, name: p, young_modulus_pa: 2.0e5, poison_ratio: 0.49}\n";
    const std::string typo = error_of(dir / "typo.yaml");
    EXPECT_NE(typo.find("typo.yaml"), std::string::npos) << typo;
    EXPECT_NE(typo.find("unknown key 'poison_ratio' in tissues[0]"), std::string::npos) << typo;
    EXPECT_NE(typo.find("did you mean 'poisson_ratio'?"), std::string::npos) << typo;
    // Misplaced: a tissue's key at the top level; unrelated: no suggestion.
    std::ofstream(dir / "misplaced.yaml") << "tissues:\n  - {label: 1, name: p, young_modulus_pa: 2.0e5, poisson_ratio: 0.4}\ndensity_kg_m3: 1000\n";
    const std::string misplaced = error_of(dir / "misplaced.yaml");
    EXPECT_NE(misplaced.find("unknown key 'density_kg_m3' in the table (accepted there: tissues, ignore_labels)"), std::string::npos) << misplaced;
    std::ofstream(dir / "json.json") << R"({"tissues": [{"label": 2, "name": "v", "young_modulus_pa": 1e6, "poisson_ratio": 0.4, "colour": "red"}]})";
    const std::string unrelated = error_of(dir / "json.json");
    EXPECT_NE(unrelated.find("unknown key 'colour' in tissues[0]"), std::string::npos) << unrelated;
    EXPECT_EQ(unrelated.find("did you mean"), std::string::npos) << unrelated;
    EXPECT_EQ(closest_key("Youngs_modulus_pa", {"young_modulus_pa", "poisson_ratio"}), "young_modulus_pa");
    EXPECT_EQ(closest_key("x", {"young_modulus_pa"}), "");
}

TEST(ModelTissueTable, RoundTrip)
{
    test::TempDir dir;
    TissueTable t = default_tissue_table();
    t.ignored_labels = {9};
    write_tissue_table(dir / "t.yaml", t);
    const auto back = read_tissue_table(dir / "t.yaml");
    ASSERT_EQ(back.tissues.size(), t.tissues.size());
    for (std::size_t i = 0; i < t.tissues.size(); ++i) {
        EXPECT_EQ(back.tissues[i].name, t.tissues[i].name);
        EXPECT_EQ(back.tissues[i].young_modulus_pa, t.tissues[i].young_modulus_pa);
        EXPECT_EQ(back.tissues[i].poisson_ratio, t.tissues[i].poisson_ratio);
    }
    EXPECT_EQ(back.ignored_labels, t.ignored_labels);
}

TEST(ModelTissueTable, ImpossibleMaterialsNameTheTissueAndParameter)
{
    test::TempDir dir;
    const std::string head = "tissues:\n  - {label: 1, name: liver, ";
    const std::pair<std::string, std::string> cases[] = {
        {"young_modulus_pa: 0, poisson_ratio: 0.45}", "young_modulus_pa"},
        {"young_modulus_pa: -5, poisson_ratio: 0.45}", "young_modulus_pa"},
        {"young_modulus_pa: .nan, poisson_ratio: 0.45}", "young_modulus_pa"},
        {"young_modulus_pa: 1e5, poisson_ratio: 0.5}", "poisson_ratio"},
        {"young_modulus_pa: 1e5, poisson_ratio: -1}", "poisson_ratio"},
        {"young_modulus_pa: 1e5, poisson_ratio: 0.3, density_kg_m3: 0}", "density_kg_m3"},
        {"young_modulus_pa: 1e5}", "poisson_ratio"},
        {"E: 1e5, poisson_ratio: 0.3}", "units"},
    };
    for (const auto& [body, expected] : cases) {
        std::ofstream(dir / "bad.yaml") << head << body << "\n";
        const std::string message = error_of(dir / "bad.yaml");
        EXPECT_NE(message.find(expected), std::string::npos) << body << " → " << message;
        EXPECT_NE(message.find("bad.yaml"), std::string::npos) << message;
    }
    std::ofstream(dir / "dup.yaml") << "tissues:\n  - {label: 1, name: a, young_modulus_pa: 1, poisson_ratio: 0.3}\n"
                                       "  - {label: 1, name: b, young_modulus_pa: 1, poisson_ratio: 0.3}\n";
    EXPECT_NE(error_of(dir / "dup.yaml").find("twice"), std::string::npos);
    std::ofstream(dir / "broken.yaml") << "tissues: [ {label: 1, name: \n";
    EXPECT_NE(error_of(dir / "broken.yaml").find("not valid"), std::string::npos);
    EXPECT_NE(error_of(dir / "missing.yaml").find("does not exist"), std::string::npos);
}

} // namespace physreg
