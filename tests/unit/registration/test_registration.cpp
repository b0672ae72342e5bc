// SPDX-License-Identifier: GPL-3.0-or-later
// The liver model variants, compression prediction, TRE and parameter estimation on the small
// phantom dataset.
#include "organs_only_phantom.hpp"
#include "test_support.hpp"

#include "physreg/evaluation/tre.hpp"
#include "physreg/figures/tre_chart.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/core/error.hpp"
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/compression/condensed_contact.hpp"
#include "physreg/registration/compression/estimation.hpp"
#include "physreg/registration/observation.hpp"
#include "physreg/io/point_cloud.hpp"
#include "physreg/mesh/labelled_boundary.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <iterator>
#include <unistd.h>

namespace physreg {
namespace {

// One small dataset for the whole suite (≈ 3 s to make).
struct SmallDataset {
    test::TempDir dir;
    PhantomDataset dataset;
    LabelVolume labels;
    LandmarkSet rest;
    SmallDataset()
    {
        // The liver models' own mechanics: the organs-only ground truth, the tool pressing the liver.
        generate_phantom_dataset(test::organs_only_small_spec(), dir / "ds", false, {});
        dataset = read_phantom_dataset(dir / "ds");
        labels = read_label_volume(dataset.path(dataset.state("rest").files.at("labels")));
        rest = read_landmarks(dataset.path(dataset.state("rest").files.at("landmarks")));
    }
};

const SmallDataset& small()
{
    static const SmallDataset d;
    return d;
}

// The organs-only ground truth presses the liver itself: the liver model is the one to test there.
ModelParameters small_model(ModelVariant variant)
{
    ModelParameters p;
    p.variant = variant;
    p.region = ModelRegion::liver;
    p.grid = {36, 27, 12}; // ≈ 5 mm cells on the small preset (4 mm voxels)
    return p;
}

TEST(Tre, StatisticsGroupsAndMissingLandmarks)
{
    const LandmarkSet truth{{"S1", {0, 0, 0}, LandmarkType::surface}, {"T1", {1, 0, 0}, LandmarkType::tumour},
                            {"V1", {0, 1, 0}, LandmarkType::vessel}, {"V2", {0, 0, 1}, LandmarkType::vessel}};
    LandmarkSet predicted = truth;
    predicted[0].position += Vec3(3, 4, 0); // 5 mm
    predicted[1].position += Vec3(0, 0, 1); // 1 mm
    predicted[2].position += Vec3(2, 0, 0); // 2 mm
    std::swap(predicted[0], predicted[3]);  // matched by name, not order
    const TreReport r = compute_tre(predicted, truth, "t");
    EXPECT_EQ(r.all.count, 4u);
    EXPECT_DOUBLE_EQ(r.all.mean_mm, 2.0);
    EXPECT_DOUBLE_EQ(r.all.max_mm, 5.0);
    EXPECT_NEAR(r.all.std_mm, std::sqrt((9.0 + 1.0 + 0.0 + 4.0) / 4.0), 1e-12);
    EXPECT_DOUBLE_EQ(r.surface.mean_mm, 5.0);
    EXPECT_DOUBLE_EQ(r.internal.mean_mm, 1.0);
    EXPECT_DOUBLE_EQ(r.tumour.mean_mm, 1.0);
    EXPECT_DOUBLE_EQ(r.vessel.mean_mm, 1.0);
    const TreReport pooled = pool_tre({r, r});
    EXPECT_EQ(pooled.all.count, 8u);
    EXPECT_DOUBLE_EQ(pooled.all.mean_mm, 2.0);
    predicted.pop_back();
    const auto message = test::error_message([&] { compute_tre(predicted, truth, "case X"); });
    EXPECT_NE(message.find("case X"), std::string::npos);
    EXPECT_NE(message.find("no prediction"), std::string::npos) << message;
    // The chart and the CSV are written.
    test::TempDir dir;
    write_tre_csv(dir / "tre.csv", r);
    std::ifstream in(dir / "tre.csv");
    std::string header;
    std::getline(in, header);
    EXPECT_NE(header.find("error_mm"), std::string::npos);
    const RgbImage chart = render_tre_chart({{"A", r}, {"B", r}}, "TRE");
    EXPECT_GT(chart.width, 100);
}

TEST(LiverModel, VariantsShareTheMeshAndPredictTheCompression)
{
    const auto& d = small();
    const auto cases = compression_cases(d.dataset, {"B"}); // the one that moves landmarks most (S06 6.6 mm)
    ASSERT_EQ(cases.size(), 1u);
    std::map<ModelVariant, TreReport> tre;
    std::string fingerprint;
    for (const auto variant : {ModelVariant::homogeneous, ModelVariant::shared_nodes, ModelVariant::coupled}) {
        const LiverModel model = build_liver_model(d.labels, d.dataset.roles, small_model(variant), "small rest");
        if (fingerprint.empty()) fingerprint = model.fingerprint;
        EXPECT_EQ(model.fingerprint, fingerprint) << "the fingerprint is of the unsplit mesh, the same for every variant";
        EXPECT_FALSE(model.fixed_nodes.empty());
        if (variant == ModelVariant::coupled) {
            EXPECT_GT(model.coupling.points().size(), 10u);
            EXPECT_GT(model.mesh.node_count(), model.original_vertex.size() - model.coupling.points().size());
        } else {
            EXPECT_TRUE(model.coupling.empty());
        }
        const auto prediction = predict_compression(model, cases[0].tool, d.rest, {}, "B");
        EXPECT_GT(prediction.max_displacement_mm, 0.5 * d.dataset.state("B").depth_mm);
        if (variant == ModelVariant::coupled) {
            // Through the shared model type (issue 29) and back: the same model, the same bits.
            const LiverModel again = compression_model(to_model(model), "round trip");
            EXPECT_EQ(again.parameters.variant, ModelVariant::coupled);
            EXPECT_EQ(again.fixed_nodes, model.fixed_nodes);
            EXPECT_EQ(predict_compression(again, cases[0].tool, d.rest, {}, "B again").displacement_mm, prediction.displacement_mm);
        }
        tre[variant] = compute_tre(prediction.landmarks, cases[0].truth, "B");
        // Landmarks the compression moved by ≥ 1 mm: the model moves them the way the ground truth
        // does (positive mean projection of the predicted on the true displacement). On the old,
        // same-family ground truth it also halved their error; against the tetrahedral
        // Mooney-Rivlin ground truth with drawn moduli it does not (2.7 vs 1.8 mm left at rest,
        // issue 17's closing note), so that is not asserted.
        double agreement = 0.0;
        int moved = 0;
        for (std::size_t i = 0; i < d.rest.size(); ++i) {
            const Vec3 truth = cases[0].truth[i].position - d.rest[i].position;
            if (truth.norm() < 1.0) continue;
            agreement += (prediction.landmarks[i].position - d.rest[i].position).dot(truth.normalized());
            ++moved;
        }
        ASSERT_GE(moved, 3);
        EXPECT_GT(agreement / moved, 0.5) << to_string(variant) << ": mean predicted displacement along the true one, mm";
        if (variant == ModelVariant::coupled) {
            EXPECT_GT(prediction.max_coupling_gap_mm, 0.0);
        }
    }
    // Paper 000's coupling (600 / 500 N/m) is soft: the coupled model differs from shared nodes.
    EXPECT_NE(tre[ModelVariant::coupled].all.mean_mm, tre[ModelVariant::shared_nodes].all.mean_mm);
}

TEST(LiverModel, NewtonAndRelaxationPredictTheSameCompression)
{
    // The 3-label phantom (parenchyma, vessels, tumours with MLS coupling): Newton's equilibrium and
    // dynamic relaxation's (tightened) agree within 1e-4 of the peak displacement, under the same
    // contact: Newton's is node-to-surface only, so relaxation's face contact is off here.
    const auto& d = small();
    const auto cases = compression_cases(d.dataset, {"B"});
    const LiverModel model = build_liver_model(d.labels, d.dataset.roles, small_model(ModelVariant::coupled), "small rest");
    PredictionOptions relaxation;
    relaxation.equilibrium.face_contact = false;
    relaxation.equilibrium.displacement_tolerance_mm = 1e-6;
    relaxation.equilibrium.residual_tolerance = 1e-7;
    relaxation.equilibrium.max_iterations = 1000000;
    PredictionOptions newton;
    newton.method = StaticMethod::newton;
    newton.newton.residual_tolerance = 1e-9;
    newton.newton.penetration_tolerance_mm = 1e-6;
    const auto a = predict_compression(model, cases[0].tool, d.rest, relaxation, "B relaxation");
    const auto b = predict_compression(model, cases[0].tool, d.rest, newton, "B newton");
    double diff = 0;
    for (std::size_t i = 0; i < a.displacement_mm.size(); ++i) diff = std::max(diff, std::abs(a.displacement_mm[i] - b.displacement_mm[i]));
    EXPECT_GT(a.max_displacement_mm, 1.0);
    EXPECT_LT(diff, 1e-4 * a.max_displacement_mm) << diff << " mm of a peak " << a.max_displacement_mm << " mm";
}

TEST(LiverModel, ParameterFileRoundTripAndBadValues)
{
    test::TempDir dir;
    ModelParameters p = small_model(ModelVariant::coupled);
    p.coupling = {1234.5, 67.25};
    p.tumour_young_pa = 3.5e6;
    write_model_parameters(dir / "p.json", p, "abc-1n-1e");
    std::string fingerprint;
    const ModelParameters q = read_model_parameters(dir / "p.json", &fingerprint);
    EXPECT_EQ(fingerprint, "abc-1n-1e");
    EXPECT_EQ(q.variant, p.variant);
    EXPECT_EQ(q.coupling.parenchyma_tumour_n_per_m, 1234.5);
    EXPECT_EQ(q.coupling.parenchyma_vessel_n_per_m, 67.25);
    EXPECT_EQ(q.tumour_young_pa, 3.5e6);
    EXPECT_EQ(q.grid, p.grid);
    // A negative stiffness in the file: refused naming the file and the parameter.
    std::ifstream in(dir / "p.json");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.replace(text.find("1234.5"), 6, "-12.5");
    std::ofstream(dir / "bad.json") << text;
    const auto message = test::error_message([&] { read_model_parameters(dir / "bad.json"); });
    EXPECT_NE(message.find("bad.json"), std::string::npos) << message;
    EXPECT_NE(message.find("k_c,s-t"), std::string::npos) << message;
    ModelParameters nan = p;
    nan.vessel_young_pa = std::nan("");
    EXPECT_NE(test::error_message([&] { nan.validate(); }).find("vessel Young's modulus"), std::string::npos);
    EXPECT_NE(test::error_message([&] { write_model_parameters(dir / "nan.json", nan, "x"); }).find("vessel"), std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(dir / "nan.json"));
    EXPECT_NE(test::error_message([] { parse_model_variant("rubber"); }).find("homogeneous, shared-nodes, coupled"), std::string::npos);
}

TEST(Estimation, FitsCouplingWithinBoundsAndReportsTrainAndValidation)
{
    const auto& d = small();
    const auto train = compression_cases(d.dataset, {"A", "B"});
    const auto validation = compression_cases(d.dataset, {"D"});
    EstimationOptions options;
    options.max_evaluations = 5;
    options.k_min_n_per_m = 10;
    options.k_max_n_per_m = 1e4;
    const auto r = estimate_parameters(d.labels, d.dataset.roles, small_model(ModelVariant::coupled), d.rest, train, validation, options);
    EXPECT_LE(r.history.size(), 5u);
    EXPECT_GE(r.history.size(), 3u);
    for (const double k : {r.fitted.coupling.parenchyma_tumour_n_per_m, r.fitted.coupling.parenchyma_vessel_n_per_m}) {
        EXPECT_GE(k, 10.0 * (1 - 1e-9));
        EXPECT_LE(k, 1e4 * (1 + 1e-9));
    }
    // The objective is the pooled training TRE at the fitted parameters, and the best seen.
    EXPECT_NEAR(r.objective_mm, r.train_pooled.all.mean_mm, 1e-12);
    for (const auto& step : r.history) EXPECT_GE(step.objective_mm, r.objective_mm - 1e-12);
    EXPECT_EQ(r.train.size(), 2u);
    EXPECT_EQ(r.validation.size(), 1u);
    // Identifiability from BOBYQA's one-parameter steps: one entry per fitted parameter, each
    // resting on at least one step (its first steps move one parameter at a time), its slope the
    // objective change over that step.
    ASSERT_EQ(r.sensitivity.size(), 2u);
    EXPECT_EQ(r.free_parameters, (std::vector<std::string>{"k_c_s_t_n_per_m", "k_c_s_v_n_per_m"}));
    for (const auto& s : r.sensitivity) {
        EXPECT_GE(s.evaluations, 1) << s.parameter;
        EXPECT_GE(s.mm_per_decade, 0.0);
        EXPECT_EQ(s.identifiable, s.mm_per_decade >= EstimationResult::identifiable_mm_per_decade);
    }
    const double slope = std::abs(r.history[1].objective_mm - r.history[0].objective_mm) /
                         std::abs(std::log10(r.history[1].parameters.coupling.parenchyma_tumour_n_per_m /
                                             r.history[0].parameters.coupling.parenchyma_tumour_n_per_m));
    EXPECT_GE(r.sensitivity[0].mm_per_decade, slope * (1 - 1e-9));
    EXPECT_EQ(r.infeasible_evaluations, 0);
    EXPECT_EQ(r.validation_pooled.all.count, d.rest.size());
    // Bad input: a training compression without landmarks, no training set, an impossible bound.
    auto empty = train;
    empty[1].truth.clear();
    EXPECT_NE(test::error_message([&] { estimate_parameters(d.labels, d.dataset.roles, small_model(ModelVariant::coupled), d.rest, empty, {}, options); })
                  .find("training compression B has no landmarks"),
              std::string::npos);
    EXPECT_NE(test::error_message([&] { estimate_parameters(d.labels, d.dataset.roles, small_model(ModelVariant::coupled), d.rest, {}, {}, options); })
                  .find("no training compression"),
              std::string::npos);
    options.k_min_n_per_m = -1;
    EXPECT_NE(test::error_message([&] { options.validate(); }).find("bounds"), std::string::npos);
    EXPECT_NE(test::error_message([&] { compression_cases(d.dataset, {"insufflation"}); }).find("not a tool compression"), std::string::npos);
    EXPECT_NE(test::error_message([&] { compression_cases(d.dataset, {"Q"}); }).find("no state 'Q'"), std::string::npos);
}

} // namespace
} // namespace physreg

namespace physreg {
namespace {

TEST(LiverModel, DefaultGridComesFromTheLiverExtentInVoxels)
{
    // A 100 × 30 × 8-voxel image whose liver (with a lesion) spans voxels 10…89 × 5…24 × 2…5:
    // 80 × 20 × 4 voxels. Paper 000's 74 × 54 × 18 cells fit along x only.
    const LabelRoles roles = phantom_label_roles();
    const auto liver = static_cast<std::uint16_t>(*roles.liver.begin());
    const auto lesion = static_cast<std::uint16_t>(*roles.lesion.begin());
    const auto body = static_cast<std::uint16_t>(*roles.body.begin());
    const LabelVolume volume = test::make_volume({100, 30, 8}, [&](int i, int j, int k) -> std::uint16_t {
        if (i == 89 && j == 24 && k == 5) return lesion;
        if (i >= 10 && i < 89 && j >= 5 && j < 25 && k >= 2 && k < 6) return liver;
        return body;
    });
    const Index3 grid = default_liver_grid(volume, roles);
    EXPECT_EQ(grid, (Index3{74, 20, 4}));
    EXPECT_EQ(default_liver_grid(volume, roles, Index3{24, 18, 18}), (Index3{24, 18, 4}));
    // The grid meshes: every target cell holds at least one voxel.
    ModelParameters p;
    p.variant = ModelVariant::homogeneous;
    p.region = ModelRegion::liver;
    p.grid = grid;
    const LiverModel model = build_liver_model(volume, roles, p, "synthetic");
    EXPECT_GT(model.mesh.cell_count(), 0u);
    // No liver label: an error that names the labels looked for.
    const LabelVolume empty = test::make_volume({10, 10, 10}, [&](int, int, int) { return body; });
    EXPECT_NE(test::error_message([&] { default_liver_grid(empty, roles); }).find("no liver label"), std::string::npos);
}

} // namespace
} // namespace physreg

namespace physreg {
namespace {

// The body model on the body ground truth: the small preset's dataset that ctest makes once
// (fixture.phantom_small; PHYSREG_TEST_PHANTOM names it). Its tool presses the skin.
struct BodyDataset {
    PhantomDataset dataset;
    LabelVolume labels;
    LandmarkSet rest;
    explicit BodyDataset(const std::filesystem::path& dir)
    {
        dataset = read_phantom_dataset(dir);
        labels = read_label_volume(dataset.path(dataset.state("rest").files.at("labels")));
        rest = read_landmarks(dataset.path(dataset.state("rest").files.at("landmarks")));
    }
};

const BodyDataset* body_dataset()
{
    static const std::unique_ptr<BodyDataset> d = [] {
        const char* dir = std::getenv("PHYSREG_TEST_PHANTOM");
        return dir && *dir ? std::make_unique<BodyDataset>(dir) : nullptr;
    }();
    return d.get();
}

ModelParameters coarse_body_model()
{
    ModelParameters p; // region body, coupled, literature moduli
    p.grid = {27, 20, 13}; // ≈ 10 mm cells over the small preset's body
    return p;
}

TEST(BodyModel, TheToolOnTheSkinMovesTheLiverTowardTheTruth)
{
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    // Supports as in the image: the bone cells' nodes held, the flat base on the table (y only).
    EXPECT_FALSE(body.fixed_nodes.empty());
    EXPECT_FALSE(body.table_nodes.empty());
    ASSERT_EQ(body.supports().size(), 2u);
    EXPECT_EQ(body.supports()[1].dofs, (std::array<bool, 3>{false, true, false}));
    double y_max = -1e300;
    for (const auto& x : body.mesh.nodes) y_max = std::max(y_max, x.y());
    for (const auto n : body.table_nodes) EXPECT_GT(body.mesh.nodes[static_cast<std::size_t>(n)].y(), y_max - body.cell_size_mm.y());
    const auto prediction = predict_compression(body, cases[0].tool, d->rest, {}, "B");
    const TreReport model = compute_tre(prediction.landmarks, cases[0].truth, "B");
    const TreReport at_rest = compute_tre(d->rest, cases[0].truth, "B at rest");
    // Motion toward the truth, not only its direction: the model's error is clearly below the
    // landmarks left at rest, for all landmarks and for the internal ones it never sees.
    EXPECT_LT(model.all.mean_mm, 0.85 * at_rest.all.mean_mm) << model.all.mean_mm << " vs " << at_rest.all.mean_mm << " mm at rest";
    EXPECT_LT(model.internal.mean_mm, 0.85 * at_rest.internal.mean_mm) << model.internal.mean_mm << " vs " << at_rest.internal.mean_mm;
    // The liver alone, held at its back, never meets a tool that stays in the gel: why the body.
    ModelParameters liver = coarse_body_model();
    liver.region = ModelRegion::liver;
    liver.grid = {23, 17, 9};
    const LiverModel alone = build_liver_model(d->labels, d->dataset.roles, liver, "small rest");
    EXPECT_TRUE(alone.table_nodes.empty());
    EXPECT_LT(predict_compression(alone, cases[0].tool, d->rest, {}, "B liver").max_displacement_mm, 1e-6);
}

TEST(BodyModel, CondensedContactMatchesTheNonlinearModelForASmallTravel)
{
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    // The tool 1.5 mm past first contact: small strains, where the linearised model must agree with
    // the Neo-Hookean one solved to equilibrium by dynamic relaxation (a different solver).
    Indenter tool = cases[0].tool;
    const Vec3 direction = (tool.path.back() - tool.path.front()).normalized();
    const Vec3 end = tool.path.front() + 1.5 * direction;
    tool.path = {tool.path.front(), end};
    std::vector<Vec3> around;
    for (const auto& l : d->rest) around.push_back(l.position);
    const auto query = nodes_near(body.mesh, around, 2.0 * body.cell_size_mm.maxCoeff());
    CondensedContactModel condensed(body, {tool}, query);
    EXPECT_GT(condensed.precomputation().candidate_nodes, 10u);
    CondensedContactModel::Update up;
    for (int step = 1; step <= 3; ++step) up = condensed.move_to(tool, tool.path.front() + (1.5 * step / 3.0) * direction);
    EXPECT_GT(up.active_nodes, 0);
    EXPECT_LE(up.max_penetration_mm, 1e-3);
    // The query nodes are the whole field's values there (one back-substitution with the forces).
    const auto full = condensed.full_displacement_mm();
    double consistency = 0.0;
    for (std::size_t i = 0; i < query.size(); ++i)
        for (int c = 0; c < 3; ++c)
            consistency = std::max(consistency, std::abs(full[3 * static_cast<std::size_t>(query[i]) + static_cast<std::size_t>(c)] -
                                                         condensed.query_displacement_mm()[3 * i + static_cast<std::size_t>(c)]));
    EXPECT_LT(consistency, 1e-8);
    // Against the nonlinear model: the landmarks' displacements agree within 15 % of the largest.
    const auto nonlinear = predict_compression(body, tool, d->rest, {}, "B, 1.5 mm");
    const LandmarkSet linear = move_landmarks(body, full, d->rest);
    double largest = 0.0, difference = 0.0;
    for (std::size_t i = 0; i < d->rest.size(); ++i) {
        largest = std::max(largest, (nonlinear.landmarks[i].position - d->rest[i].position).norm());
        difference = std::max(difference, (nonlinear.landmarks[i].position - linear[i].position).norm());
    }
    EXPECT_GT(largest, 0.05);
    EXPECT_LT(difference, 0.15 * largest) << difference << " mm vs the largest landmark motion " << largest << " mm";
    std::printf("condensed vs nonlinear at 1.5 mm: largest landmark motion %.4f mm, largest difference %.4f mm; %zu candidates, %d in contact\n",
                largest, difference, condensed.precomputation().candidate_nodes, up.active_nodes);
}

TEST(BodyModel, ACondensedToolOffTheSessionPathsAddsItsNodesAndGivesTheFullAnswer)
{
    // Bad input of issue 30: a tool position outside the precomputed candidate region must not be
    // answered from the stale block (its nodes would be pushed through). The model precomputed for
    // B's path alone, moved along D's, adds the nodes D reaches (solves with the factor, a warning)
    // and then answers as the model precomputed for both paths does.
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B", "D"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    std::vector<Vec3> around;
    for (const auto& l : d->rest) around.push_back(l.position);
    const auto query = nodes_near(body.mesh, around, 2.0 * body.cell_size_mm.maxCoeff());
    CondensedContactModel only_b(body, {cases[0].tool}, query);
    CondensedContactModel both(body, {cases[0].tool, cases[1].tool}, query);
    const std::size_t precomputed_b = only_b.precomputation().candidate_nodes;
    ASSERT_GT(both.precomputation().candidate_nodes, precomputed_b) << "D's path must reach other skin nodes than B's";
    const Indenter& tool = cases[1].tool;
    const Vec3 direction = (tool.path.back() - tool.path.front()).normalized();
    double largest = 0.0, difference = 0.0;
    int added = 0;
    for (int step = 1; step <= 3; ++step) {
        const Vec3 at = tool.path.front() + 1.0 * step * direction;
        const auto up = only_b.move_to(tool, at);
        const auto reference = both.move_to(tool, at);
        added += up.added_candidates;
        if (step == 1) EXPECT_GT(up.added_candidates, 0) << "the first update off B's path adds D's nodes";
        else EXPECT_EQ(up.added_candidates, 0) << "later updates nearby reuse them";
        EXPECT_EQ(up.active_nodes, reference.active_nodes);
        EXPECT_LE(up.max_penetration_mm, 1e-3);
        for (std::size_t i = 0; i < only_b.query_displacement_mm().size(); ++i) {
            largest = std::max(largest, std::abs(reference.active_nodes > 0 ? both.query_displacement_mm()[i] : 0.0));
            difference = std::max(difference, std::abs(only_b.query_displacement_mm()[i] - both.query_displacement_mm()[i]));
        }
    }
    EXPECT_EQ(only_b.precomputation().region_extensions, 1);
    EXPECT_EQ(only_b.precomputation().added_candidates, static_cast<std::size_t>(added));
    EXPECT_EQ(only_b.candidate_nodes().size(), precomputed_b + static_cast<std::size_t>(added));
    EXPECT_GT(largest, 0.01);
    EXPECT_LT(difference, 1e-6 * largest + 1e-9) << difference << " mm of " << largest;
    std::printf("tool off the session's paths: %zu candidates precomputed for B, %d added for D; query nodes within %.3g mm of the model "
                "precomputed for both (largest motion %.3f mm)\n",
                precomputed_b, added, difference, largest);

    // A memory budget below what the precomputation needs: an error naming both sizes.
    CondensedContactOptions tight;
    tight.memory_limit_bytes = 1u << 20;
    try {
        CondensedContactModel refused(body, {cases[0].tool}, query, tight);
        ADD_FAILURE() << "a 1 MiB budget was accepted";
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("over the memory limit of 1.0 MiB"), std::string::npos) << what;
        EXPECT_NE(what.find("needs ≈"), std::string::npos) << what;
    }
}

TEST(BodyModel, StoredCondensedComplianceAnswersAsTheOriginalAndRefusesAnotherModel)
{
    // physreg prepare → serve (issue 44 item 3): the compliance blocks written, read back and
    // given to a model that was never factorised answer every update exactly as the original does;
    // the factor is made only when the whole field is asked for. Corrupt, truncated or foreign
    // files are refused with the file named.
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    std::vector<Vec3> around;
    for (const auto& l : d->rest) around.push_back(l.position);
    const auto query = nodes_near(body.mesh, around, 2.0 * body.cell_size_mm.maxCoeff());
    CondensedContactModel original(body, {cases[0].tool}, query);
    const auto dir = std::filesystem::temp_directory_path() / ("physreg_condensed_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    const auto file = dir / "condensed.bin";
    write_condensed_compliance(file, original.compliance());
    CondensedContactModel stored(body, read_condensed_compliance(file));
    EXPECT_FALSE(stored.factorised());
    const Indenter& tool = cases[0].tool;
    const Vec3 direction = (tool.path.back() - tool.path.front()).normalized();
    for (int step = 1; step <= 4; ++step) {
        const Vec3 at = tool.path.front() + 1.5 * step * direction;
        const auto a = original.move_to(tool, at);
        const auto b = stored.move_to(tool, at);
        EXPECT_EQ(a.active_nodes, b.active_nodes);
        EXPECT_EQ(original.query_displacement_mm(), stored.query_displacement_mm()) << "step " << step; // bit for bit: the same blocks
    }
    EXPECT_FALSE(stored.factorised()) << "tool updates on the session's path need no factor";
    const auto full_a = original.full_displacement_mm(), full_b = stored.full_displacement_mm();
    EXPECT_TRUE(stored.factorised());
    double difference = 0.0, largest = 0.0;
    for (std::size_t i = 0; i < full_a.size(); ++i) {
        difference = std::max(difference, std::abs(full_a[i] - full_b[i]));
        largest = std::max(largest, std::abs(full_a[i]));
    }
    EXPECT_GT(largest, 0.1);
    EXPECT_LT(difference, 1e-10 * largest);

    // Bad files: truncated, one byte changed, not ours; and blocks of another model.
    std::string bytes;
    {
        std::ifstream in(file, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    const auto expect_refused = [&](const std::string& content, const std::string& words) {
        std::ofstream(dir / "bad.bin", std::ios::binary) << content;
        try {
            (void)read_condensed_compliance(dir / "bad.bin");
            ADD_FAILURE() << "accepted: " << words;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("bad.bin"), std::string::npos) << e.what();
        }
    };
    expect_refused(bytes.substr(0, bytes.size() / 2), "checksum");
    std::string flipped = bytes;
    flipped[flipped.size() / 3] ^= 0x10;
    expect_refused(flipped, "checksum");
    expect_refused("not a physreg file at all", "wrong magic");
    ModelParameters other = coarse_body_model();
    other.body_young_pa *= 2.0; // same mesh, another stiffness
    const LiverModel stiffer = build_liver_model(d->labels, d->dataset.roles, other, "small rest, stiffer gel");
    try {
        CondensedContactModel wrong(stiffer, read_condensed_compliance(file));
        ADD_FAILURE() << "blocks of another stiffness were accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("another stiffness"), std::string::npos) << e.what();
    }
    std::filesystem::remove_all(dir);
}

TEST(BodyModel, ASolveThatFailsUnderTheToolFallsBackToTheLinearisedModel)
{
    // Issue 46 item 2: a hard case is not bad input. Where the Neo-Hookean model folds an element on
    // every try or its solve stalls, the prediction comes from the model linearised at rest with condensed contact,
    // says why, and equals that solver's own answer.
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    // A solve that stalls (here: an iteration budget far too small for B's 15 mm push) gets the
    // same treatment as one that folds an element (the study's d00 B, a 20 mm sphere 20 mm deep).
    const Indenter& tool = cases[0].tool;
    PredictionOptions options;
    options.equilibrium.max_iterations = 50;
    std::string fallback;
    const CompressionPrediction p = predict_compression_with_fallback(body, tool, d->rest, options, "B", 5, {}, &fallback);
    ASSERT_FALSE(fallback.empty()) << "the solve did not stall: the test no longer shows the fallback";
    EXPECT_NE(fallback.find("stalled"), std::string::npos) << fallback;
    EXPECT_NE(fallback.find("condensed contact"), std::string::npos) << fallback;
    const CompressionPrediction reference = predict_compression_condensed(body, tool, d->rest, 5, "B");
    ASSERT_EQ(p.displacement_mm.size(), reference.displacement_mm.size());
    double difference = 0.0;
    for (std::size_t i = 0; i < p.displacement_mm.size(); ++i) difference = std::max(difference, std::abs(p.displacement_mm[i] - reference.displacement_mm[i]));
    EXPECT_LT(difference, 1e-9);
    EXPECT_GT(p.max_displacement_mm, 1.0);
    // Without folding (the default ramp), no fallback: the Neo-Hookean answer.
    std::string none;
    (void)predict_compression_with_fallback(body, cases[0].tool, d->rest, PredictionOptions{}, "B", 5, {}, &none);
    EXPECT_TRUE(none.empty()) << none;
}

TEST(BodyModel, APartialLiverSurfaceCloudDrivesTheBodyModel)
{
    // Cross-mode (issue 29): paper 001's observation — a partial surface of the liver, seen after
    // compression B — drives paper 000's body model (gel, organs, bone held, the base on the table)
    // through paper 001's solver (co-rotational backward Euler under annealed pair forces). The
    // cloud is the ground truth's (Mooney–Rivlin tetrahedra, another model); the landmarks are
    // judged against it and never seen.
    const BodyDataset* d = body_dataset();
    if (!d) PHYSREG_MISSING_FIXTURE("PHYSREG_TEST_PHANTOM is not set (ctest's fixture.phantom_small sets it)");
    const auto cases = compression_cases(d->dataset, {"B"});
    const LiverModel body = build_liver_model(d->labels, d->dataset.roles, coarse_body_model(), "small rest");
    const auto& roles = d->dataset.roles;
    std::set<std::int32_t> liver(roles.liver.begin(), roles.liver.end());
    liver.insert(roles.lesion.begin(), roles.lesion.end());
    liver.insert(roles.vessel.begin(), roles.vessel.end());
    const Model model = to_model(body, liver);
    ASSERT_FALSE(model.surface.triangles.empty());
    ASSERT_TRUE(model.coupling);
    // The surface is the liver's boundary, not the split interfaces of its lesions and vessels: the
    // same faces as the model whose tissues share their nodes.
    ModelParameters shared = coarse_body_model();
    shared.variant = ModelVariant::shared_nodes;
    EXPECT_EQ(model.surface.triangles.size(), to_model(build_liver_model(d->labels, roles, shared, "small rest"), liver).surface.triangles.size());
    ASSERT_FALSE(model.partial_supports().empty()) << "the table holds y only";
    const auto& state = d->dataset.state("B");
    ASSERT_FALSE(state.surfaces.empty());
    CloudObservation seen{read_point_cloud(d->dataset.path(state.surfaces.rbegin()->second.first))};
    for (auto& label : seen.cloud.labels) label = feature_none; // the body model's liver surface has no regions
    const ModelRegistration r = register_model(model, seen);
    EXPECT_EQ(r.mode, "surface");
    std::vector<Vec3> rest;
    for (const auto& l : d->rest) rest.push_back(l.position);
    const auto moved = displace_points(model, r.displacement_mm, rest, body.cell_size_mm.maxCoeff(), "landmarks");
    LandmarkSet predicted = d->rest;
    for (std::size_t i = 0; i < moved.size(); ++i) predicted[i].position = moved[i];
    const TreReport tre = compute_tre(predicted, cases[0].truth, "B from the cloud");
    const TreReport at_rest = compute_tre(d->rest, cases[0].truth, "B at rest");
    std::printf("body model driven by B's %d %% liver surface cloud (%zu points): TRE %.3f mm (internal %.3f) vs %.3f (%.3f) at rest, %.1f s\n",
                state.surfaces.rbegin()->first, seen.cloud.points.size(), tre.all.mean_mm, tre.internal.mean_mm, at_rest.all.mean_mm,
                at_rest.internal.mean_mm, r.seconds);
    // Measured 0.84× (internal 0.90×) on the Release fixture, 0.87× (0.93×) on the fixture an ASan
    // build makes: about what the tool alone gives this coarse model (10 mm cells, whose voxelised
    // liver surface lies up to half a cell from the smooth one the cloud samples; a 7 mm grid gave
    // the same TRE in 6× the time).
    EXPECT_LT(tre.all.mean_mm, 0.95 * at_rest.all.mean_mm);
    EXPECT_LT(tre.internal.mean_mm, at_rest.internal.mean_mm);
}

TEST(BodyModel, ParameterFilesKeepTheRegionAndOldFilesAreLiverModels)
{
    test::TempDir dir;
    ModelParameters p = coarse_body_model();
    p.body_young_pa = 3.25e4;
    write_model_parameters(dir / "p.json", p, "abc-1n-1e");
    const ModelParameters q = read_model_parameters(dir / "p.json");
    EXPECT_EQ(q.region, ModelRegion::body);
    EXPECT_EQ(q.body_young_pa, 3.25e4);
    // A version-1 file (before the body model) describes the liver alone.
    std::ifstream in(dir / "p.json");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.replace(text.find("\"format_version\": 2"), 19, "\"format_version\": 1");
    text.replace(text.find("\"region\": \"body\""), 16, "\"region\": \"liver\"");
    std::ofstream(dir / "v1.json") << text;
    EXPECT_EQ(read_model_parameters(dir / "v1.json").region, ModelRegion::liver);
    EXPECT_NE(test::error_message([] { parse_model_region("torso"); }).find("body, liver"), std::string::npos);
    ModelParameters bad = p;
    bad.body_young_pa = -1;
    EXPECT_NE(test::error_message([&] { bad.validate(); }).find("body (gel) Young's modulus"), std::string::npos);
    // A label map without a body label (none named, none left over): an error naming the labels found.
    const LabelRoles roles = phantom_label_roles();
    const auto liver_label = static_cast<std::uint16_t>(*roles.liver.begin());
    const LabelVolume liver_only = test::make_volume({12, 12, 12}, [&](int i, int j, int k) -> std::uint16_t {
        return i > 2 && i < 9 && j > 2 && j < 9 && k > 2 && k < 9 ? liver_label : 0;
    });
    ModelParameters small = coarse_body_model();
    small.grid = {6, 6, 6};
    const auto message = test::error_message([&] { build_liver_model(liver_only, roles, small, "liver.nii"); });
    EXPECT_NE(message.find("no body label"), std::string::npos) << message;
    EXPECT_NE(message.find("labels found: 0,2"), std::string::npos) << message;
}

} // namespace
} // namespace physreg
