// SPDX-License-Identifier: GPL-3.0-or-later
// The settings specification (issue 43): one table of keys, options, ranges and defaults that the
// command line, Python, settings files and summary.json all read.
#include "physreg/core/error.hpp"
#include "physreg/core/settings_spec.hpp"
#include "physreg/io/settings_file.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/images/image_registration.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

using namespace physreg;

namespace {

struct Toy {
    double size = 2.0;
    int steps = 3;
    bool fast = true;
    std::string law = "linear";
    std::vector<std::int32_t> labels;
};

const SettingsSpec<Toy>& toy_spec()
{
    static const SettingsSpec<Toy> spec = [] {
        SettingsSpec<Toy> s("toy");
        s.real("size", "--size", &Toy::size, "mm", "a size", 0.0, 10.0, true)
            .integer("steps", "--steps", &Toy::steps, "steps", 1, 100)
            .flag("fast", "!--slow", &Toy::fast, "fast")
            .choice("law", "--law", &Toy::law, {"linear", "corotational"}, "the law")
            .labels("labels", "--labels", &Toy::labels, "labels");
        return s;
    }();
    return spec;
}

std::string error_of(const std::function<void()>& f) { return test::error_message(f); }

} // namespace

TEST(SettingsSpec, RoundTripsEverySettingThroughJson)
{
    Toy t;
    t.size = 4.5;
    t.steps = 7;
    t.fast = false;
    t.law = "corotational";
    t.labels = {2, 5};
    const nlohmann::json j = toy_spec().to_json(t);
    EXPECT_EQ(j.dump(), R"({"fast":false,"labels":[2,5],"law":"corotational","size":4.5,"steps":7})");
    Toy back;
    toy_spec().apply(back, j, "test");
    EXPECT_EQ(toy_spec().to_json(back), j);
}

TEST(SettingsSpec, RefusesUnknownKeysWithTheNearestAndWrongTypes)
{
    Toy t;
    const std::string unknown = error_of([&] { toy_spec().apply(t, nlohmann::json{{"sise", 1.0}}, "cfg.yaml"); });
    EXPECT_NE(unknown.find("cfg.yaml: unknown key 'sise'"), std::string::npos) << unknown;
    EXPECT_NE(unknown.find("did you mean 'size'"), std::string::npos) << unknown;
    EXPECT_NE(error_of([&] { toy_spec().apply(t, nlohmann::json{{"size", "big"}}, "cfg"); }).find("cfg: size: expected a number"), std::string::npos);
    EXPECT_NE(error_of([&] { toy_spec().apply(t, nlohmann::json{{"steps", 2.5}}, "cfg"); }).find("whole number"), std::string::npos);
    EXPECT_NE(error_of([&] { toy_spec().apply(t, nlohmann::json{{"fast", 1}}, "cfg"); }).find("expected true or false"), std::string::npos);
    EXPECT_NE(error_of([&] { toy_spec().apply(t, nlohmann::json{{"labels", {2, 0}}}, "cfg"); }).find("'0' is not a label"), std::string::npos);
    EXPECT_NE(error_of([&] { toy_spec().apply(t, nlohmann::json::array(), "cfg"); }).find("expected an object"), std::string::npos);
}

TEST(SettingsSpec, ValidatesRangesAndChoicesNamingTheSettingAsAsked)
{
    Toy t;
    t.size = 0.0; // the lower end is open
    EXPECT_EQ(error_of([&] { toy_spec().validate(t, SettingNaming::option); }), "--size 0 mm must be in (0, 10]");
    EXPECT_EQ(error_of([&] { toy_spec().validate(t, SettingNaming::key); }), "size 0 mm must be in (0, 10]");
    t.size = 10.0;
    EXPECT_EQ(error_of([&] { toy_spec().validate(t, SettingNaming::key); }), "");
    t.size = std::nan("");
    EXPECT_NE(error_of([&] { toy_spec().validate(t, SettingNaming::key); }), "");
    t.size = 1.0;
    t.steps = 0;
    EXPECT_EQ(error_of([&] { toy_spec().validate(t, SettingNaming::option); }), "--steps 0 must be in [1, 100]");
    t.steps = 1;
    t.law = "affine";
    EXPECT_EQ(error_of([&] { toy_spec().validate(t, SettingNaming::option); }), "--law 'affine': use linear or corotational");
    // A negated flag is named by its option as written.
    EXPECT_EQ(toy_spec().name("fast", SettingNaming::option), "--slow");
}

TEST(SettingsSpec, DescribesDefaultsRangesAndChoices)
{
    const nlohmann::json d = toy_spec().describe();
    EXPECT_EQ(d["size"]["default"], 2.0);
    EXPECT_EQ(d["size"]["unit"], "mm");
    EXPECT_EQ(d["size"]["range"], "in (0, 10]");
    EXPECT_EQ(d["law"]["choices"], nlohmann::json({"linear", "corotational"}));
    EXPECT_EQ(d["fast"]["option"], "--slow");
}

TEST(SettingsSpec, ReadsYamlAndJsonSettingsFiles)
{
    const auto dir = std::filesystem::temp_directory_path() / "physreg_settings_spec_test";
    std::filesystem::create_directories(dir);
    std::ofstream(dir / "a.yaml") << "size: 2.5\nsteps: 4\nfast: false\nlaw: corotational\nlabels: [3, 2]\n";
    std::ofstream(dir / "b.json") << R"({"size": 1, "labels": "7,6"})";
    std::ofstream(dir / "c.yaml") << "- 1\n- 2\n";
    Toy t;
    toy_spec().apply(t, read_settings_file(dir / "a.yaml"), "a.yaml");
    EXPECT_EQ(t.size, 2.5);
    EXPECT_EQ(t.steps, 4);
    EXPECT_FALSE(t.fast);
    EXPECT_EQ(t.law, "corotational");
    EXPECT_EQ(t.labels, (std::vector<std::int32_t>{2, 3}));
    toy_spec().apply(t, read_settings_file(dir / "b.json"), "b.json");
    EXPECT_EQ(t.size, 1.0);
    EXPECT_EQ(t.labels, (std::vector<std::int32_t>{6, 7}));
    EXPECT_NE(error_of([&] { read_settings_file(dir / "c.yaml"); }).find("expected a mapping"), std::string::npos);
    EXPECT_THROW(read_settings_file(dir / "missing.yaml"), MissingFileError);
    std::filesystem::remove_all(dir);
}

TEST(SettingsSpec, ImageRegistrationDefaultsAreTheCommandsAndValid)
{
    const ImageRegistrationSettings s;
    EXPECT_NO_THROW(validate(s, SettingNaming::option));
    const nlohmann::json j = image_registration_spec().to_json(s);
    EXPECT_EQ(j["rms_tolerance"], 0.001);
    EXPECT_EQ(j["rest_offsets"], true);
    EXPECT_EQ(j["cycles"], 40);
    const auto options = s.solver_options();
    EXPECT_EQ(options.rms_tolerance_mm, 0.001);
    EXPECT_TRUE(options.reuse_factor);
    // Every member of the struct is in the specification (a new member needs a new entry).
    EXPECT_EQ(j.size(), 27u);
    EXPECT_EQ(j["initial_max_rotation"], 60.0);
    ImageRegistrationSettings bad;
    bad.method = "rigid";
    bad.baselines = "none";
    EXPECT_EQ(error_of([&] { validate(bad, SettingNaming::key); }), "method rigid needs the baselines (baselines is none)");
    bad = {};
    bad.estimate_moduli = false;
    bad.moduli_prior = 2.0;
    EXPECT_EQ(error_of([&] { validate(bad, SettingNaming::option); }), "--moduli-prior 2 needs estimated moduli (--no-moduli is given)");
}

// Paper 000's modes share the model's entries (one CompressionSettings) and add their own.
TEST(SettingsSpec, PaperZeroModesShareTheModelEntries)
{
    const auto keys = [](const nlohmann::json& j) {
        std::vector<std::string> out;
        for (const auto& [k, v] : j.items()) out.push_back(k);
        return out;
    };
    const auto model = keys(estimation_spec().to_json({}));
    for (const auto& key : {"variant", "region", "grid", "body_modulus", "k_tumour", "k_vessel", "support_radius", "solver", "tool_speed", "tolerance", "residual"}) {
        EXPECT_TRUE(compression_spec().find(key)) << key;
        EXPECT_TRUE(estimation_spec().find(key)) << key;
        EXPECT_TRUE(enrichment_build_spec().find(key)) << key;
        EXPECT_TRUE(enrichment_apply_spec().find(key)) << key;
    }
    // Every member is in its specification: 11 model entries plus each mode's own.
    EXPECT_EQ(compression_spec().entries().size(), 14u);
    EXPECT_EQ(estimation_spec().entries().size(), 19u);
    EXPECT_EQ(enrichment_build_spec().entries().size(), 19u);
    EXPECT_EQ(enrichment_apply_spec().entries().size(), 15u);
    EXPECT_EQ(model.size(), 19u);
    // Defaults are ModelParameters' and PredictionOptions'.
    const CompressionRegistrationSettings d;
    const ModelParameters p = d.model_parameters();
    EXPECT_EQ(p.coupling.parenchyma_tumour_n_per_m, ModelParameters{}.coupling.parenchyma_tumour_n_per_m);
    EXPECT_EQ(d.prediction_options().tool_speed_per_cell, PredictionOptions{}.tool_speed_per_cell);
    EXPECT_TRUE(d.model_keys_set().empty());
    CompressionRegistrationSettings s;
    s.k_tumour = 77;
    s.grid = "12x10x6";
    EXPECT_EQ(s.model_keys_set(), (std::vector<std::string>{"grid", "k_tumour"}));
    EXPECT_EQ(error_of([&] { validate(s, SettingNaming::key); }), "");
    s.grid = "12x10";
    EXPECT_NE(error_of([&] { validate(s, SettingNaming::key); }).find("grid"), std::string::npos);
    s = {};
    s.solver = "condensed";
    EXPECT_EQ(error_of([&] { validate(s, SettingNaming::option); }), "");
    EstimationSettings e;
    e.solver = "condensed";
    EXPECT_EQ(error_of([&] { validate(e, SettingNaming::option); }), "--solver 'condensed': use relaxation or newton");
    e = {};
    e.k_min = 10, e.k_max = 5;
    EXPECT_EQ(error_of([&] { validate(e, SettingNaming::key); }), "k_max 5 N/m must exceed k_min 10 N/m");
    // Memory sizes: binary suffixes, auto is 0.
    EXPECT_EQ(parse_memory_size("auto", "m"), 0u);
    EXPECT_EQ(parse_memory_size("8G", "m"), 8ull << 30);
    EXPECT_EQ(parse_memory_size("512M", "m"), 512ull << 20);
    EXPECT_NE(error_of([&] { parse_memory_size("12Q", "--memory-limit"); }).find("--memory-limit must be auto or a positive size"), std::string::npos);
    EXPECT_EQ(split_names("A,,B,", "--train"), (std::vector<std::string>{"A", "B"}));
    EXPECT_NE(error_of([&] { split_names(",", "--train"); }).find("--train: no state names"), std::string::npos);
}
