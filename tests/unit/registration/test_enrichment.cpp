// SPDX-License-Identifier: GPL-3.0-or-later
// Detail enrichment (paper 000 eqs. 9–10): exact reproduction of a training condition and the
// database file's round trip and corruption checks.
#include "organs_only_phantom.hpp"
#include "test_support.hpp"

#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/compression/condensed_coarse_to_fine.hpp"
#include "physreg/registration/compression/enrichment.hpp"
#include "physreg/registration/compression/estimation.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <tuple>
#include <omp.h>

namespace physreg {
namespace {

struct TwoLevels {
    test::TempDir dir;
    LiverModel fine, coarse;
    std::vector<NodeEmbedding> embedding;
    std::vector<double> fine_u, coarse_u;
    EnrichmentCondition condition;
    TwoLevels()
    {
        // The liver models' own mechanics: the organs-only ground truth, the tool pressing the liver.
        generate_phantom_dataset(test::organs_only_small_spec(), dir / "ds", false, {});
        const PhantomDataset d = read_phantom_dataset(dir / "ds");
        const LabelVolume labels = read_label_volume(d.path(d.state("rest").files.at("labels")));
        ModelParameters p;
        p.region = ModelRegion::liver;
        p.grid = {36, 27, 12};
        fine = build_liver_model(labels, d.roles, p, "small rest");
        coarse = coarsen_liver_model(fine, {12, 9, 6}, &embedding);
        const auto cases = compression_cases(d, {"B"});
        fine_u = predict_compression(fine, cases[0].tool, {}, {}, "fine B").displacement_mm;
        coarse_u = predict_compression(coarse, cases[0].tool, {}, {}, "coarse B").displacement_mm;
        condition = {"B", cases[0].tool.path.front(), (cases[0].tool.path.back() - cases[0].tool.path.front()).normalized(),
                     (cases[0].tool.path.back() - cases[0].tool.path.front()).norm()};
    }
};

const TwoLevels& levels()
{
    static const TwoLevels t;
    return t;
}

TEST(CoarseModel, MajorityCoarseningKeepsTissuesAndSupport)
{
    const auto& t = levels();
    EXPECT_EQ(t.coarse.mesh.grid->dims, (Index3{12, 9, 6}));
    EXPECT_TRUE(t.coarse.coupling.empty());
    EXPECT_FALSE(t.coarse.fixed_nodes.empty());
    EXPECT_EQ(t.embedding.size(), t.fine.mesh.node_count());
    std::set<std::int32_t> labels(t.coarse.mesh.cell_labels.begin(), t.coarse.mesh.cell_labels.end());
    EXPECT_TRUE(labels.count(2)); // parenchyma
    double largest = 0.0;
    for (std::size_t n = 0; n < t.coarse.mesh.node_count(); ++n)
        largest = std::max(largest, Vec3(t.coarse_u[3 * n], t.coarse_u[3 * n + 1], t.coarse_u[3 * n + 2]).norm());
    EXPECT_GT(largest, 3.0); // the coarse model follows the tool too
}

TEST(Enrichment, SynthesisReproducesTheTrainingConditionExactly)
{
    const auto& t = levels();
    const auto phi = enrichment_weights(t.coarse.mesh, t.coarse_u, t.embedding, t.fine.mesh.nodes, t.fine_u);
    const auto u = synthesize_fine_displacement(t.coarse.mesh, t.coarse_u, t.embedding, t.fine.mesh.nodes, phi);
    double worst = 0.0, coarse_only = 0.0;
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); ++j) {
        worst = std::max(worst, Vec3(u[3 * j] - t.fine_u[3 * j], u[3 * j + 1] - t.fine_u[3 * j + 1], u[3 * j + 2] - t.fine_u[3 * j + 2]).norm());
        // The coarse model's own interpolation misses the detail (so the check above is not trivial).
        NodeEmbedding e = t.embedding[j];
        e.natural = e.natural.cwiseMax(-1.0).cwiseMin(1.0);
        const auto c = interpolate_nodal(t.coarse.mesh, e, t.coarse_u, 3);
        coarse_only = std::max(coarse_only, Vec3(c[0] - t.fine_u[3 * j], c[1] - t.fine_u[3 * j + 1], c[2] - t.fine_u[3 * j + 2]).norm());
    }
    EXPECT_LT(worst, 1e-6) << "mm";
    EXPECT_GT(coarse_only, 0.1);
    // Partition of unity of the stored weights.
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); j += 97) {
        double sum = 0.0;
        for (int k = 0; k < 8; ++k) sum += phi[8 * j + k];
        EXPECT_NEAR(sum, 1.0, 1e-5);
    }
}

EnrichmentDatabase small_database()
{
    const auto& t = levels();
    EnrichmentDatabase db;
    db.fine_fingerprint = t.fine.fingerprint;
    db.coarse_fingerprint = t.coarse.fingerprint;
    db.model_json = R"({"variant":"coupled"})";
    db.fine_nodes = t.fine.mesh.node_count();
    db.coarse_nodes = t.coarse.mesh.node_count();
    for (int copy = 0; copy < 3; ++copy) {
        EnrichmentCondition c = t.condition;
        c.depth_mm += copy;
        db.conditions.push_back(c);
        db.coarse_displacement.emplace_back(t.coarse_u.begin(), t.coarse_u.end());
        db.weights.push_back(enrichment_weights(t.coarse.mesh, t.coarse_u, t.embedding, t.fine.mesh.nodes, t.fine_u));
        db.weights.back()[static_cast<std::size_t>(copy)] += 0.25f * float(copy);
    }
    return db;
}

TEST(EnrichmentDatabase, RoundTripIsExact)
{
    const EnrichmentDatabase db = small_database();
    test::TempDir dir;
    write_enrichment_database(dir / "db.phe", db);
    const EnrichmentDatabase back = read_enrichment_database(dir / "db.phe");
    EXPECT_EQ(back.fine_fingerprint, db.fine_fingerprint);
    EXPECT_EQ(back.coarse_fingerprint, db.coarse_fingerprint);
    EXPECT_EQ(back.fine_nodes, db.fine_nodes);
    ASSERT_EQ(back.conditions.size(), 3u);
    for (std::size_t t = 0; t < 3; ++t) {
        EXPECT_EQ(back.conditions[t].position, db.conditions[t].position);
        EXPECT_EQ(back.conditions[t].contact_mm, db.conditions[t].contact_mm);
        EXPECT_EQ(back.conditions[t].direction, db.conditions[t].direction);
        EXPECT_EQ(back.conditions[t].depth_mm, db.conditions[t].depth_mm);
        EXPECT_EQ(back.weights[t], db.weights[t]); // bit-exact floats
        EXPECT_EQ(back.coarse_displacement[t], db.coarse_displacement[t]);
    }
    EXPECT_NE(back.model_json.find("\"variant\":\"coupled\""), std::string::npos) << back.model_json;
}

TEST(EnrichmentDatabase, TruncatedOrBitFlippedFilesAreRejected)
{
    const EnrichmentDatabase db = small_database();
    test::TempDir dir;
    write_enrichment_database(dir / "db.phe", db);
    std::ifstream in(dir / "db.phe", std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir / "cut.phe", std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size() - 1000));
    const auto truncated = test::error_message([&] { read_enrichment_database(dir / "cut.phe"); });
    EXPECT_NE(truncated.find("truncated"), std::string::npos) << truncated;
    EXPECT_NE(truncated.find("cut.phe"), std::string::npos);
    // One bit flipped in the second condition's weights.
    std::string flipped = bytes;
    const std::size_t block = (3 * db.coarse_nodes + 8 * db.fine_nodes) * 4 + 4;
    const std::size_t at = bytes.size() - 12 - 2 * block + 3 * db.coarse_nodes * 4 + 400;
    flipped[at] = static_cast<char>(flipped[at] ^ 0x10);
    std::ofstream(dir / "flip.phe", std::ios::binary).write(flipped.data(), static_cast<std::streamsize>(flipped.size()));
    const auto corrupt = test::error_message([&] { read_enrichment_database(dir / "flip.phe"); });
    EXPECT_NE(corrupt.find("checksum mismatch in condition 1"), std::string::npos) << corrupt;
    // A flip in the header, and a file that is not a database.
    std::string header = bytes;
    header[30] = static_cast<char>(header[30] ^ 0x01);
    std::ofstream(dir / "head.phe", std::ios::binary).write(header.data(), static_cast<std::streamsize>(header.size()));
    EXPECT_NE(test::error_message([&] { read_enrichment_database(dir / "head.phe"); }), "");
    std::ofstream(dir / "text.phe") << "hello, this is not a database";
    EXPECT_NE(test::error_message([&] { read_enrichment_database(dir / "text.phe"); }).find("bad magic"), std::string::npos);
    // Inconsistent in memory: refused before anything is written.
    EnrichmentDatabase bad = db;
    bad.weights[2].pop_back();
    EXPECT_NE(test::error_message([&] { write_enrichment_database(dir / "bad.phe", bad); }).find("condition 2"), std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(dir / "bad.phe"));
}

} // namespace
} // namespace physreg

namespace physreg {
namespace {

TEST(EnrichmentPlan, SkinGridPositionsTouchTheBodyAboveTheLiver)
{
    // A 40 × 30 × 20-voxel body (1 mm voxels, origin 0) with a flat anterior skin at y = 5 and a liver at
    // x 10…29, z 5…14; a 4 mm ball pressing along +y first touches the skin with its centre at y = 5 − 4
    // (voxel centres, where the skin voxels sit).
    const LabelRoles roles = phantom_label_roles();
    const auto body = static_cast<std::uint16_t>(*roles.body.begin()), liver = static_cast<std::uint16_t>(*roles.liver.begin());
    const LabelVolume volume = test::make_volume({40, 30, 20}, [&](int i, int j, int k) -> std::uint16_t {
        if (j < 5) return 0;
        return i >= 10 && i < 30 && j >= 12 && j < 20 && k >= 5 && k < 15 ? liver : body;
    });
    Indenter ball;
    ball.shape = IndenterShape::sphere;
    ball.radius_mm = 4.0;
    const auto positions = skin_grid_positions(volume, roles, ball, Vec3::UnitY(), 3, 2);
    ASSERT_EQ(positions.size(), 6u);
    EXPECT_EQ(positions.front().name, "G11");
    EXPECT_EQ(positions.back().name, "G32");
    for (const auto& p : positions) {
        // The skin is sampled at voxel centres: a line between them meets the ball's pole up to
        // r − √(r² − 0.5) ≈ 0.06 mm later.
        EXPECT_GE(p.contact_mm.y(), 1.0 - 1e-9) << p.name;
        EXPECT_LE(p.contact_mm.y(), 1.07) << p.name;
        EXPECT_GE(p.contact_mm.x(), 10.0 - 1e-9);
        EXPECT_LE(p.contact_mm.x(), 29.0 + 1e-9);
        EXPECT_GE(p.contact_mm.z(), 5.0 - 1e-9);
        EXPECT_LE(p.contact_mm.z(), 14.0 + 1e-9);
    }
    // Evenly over the central 70 % of the liver's 19 mm (voxel centres 10…29) across x.
    EXPECT_NEAR(positions[2].contact_mm.x() - positions[0].contact_mm.x(), 0.35 * 19.0, 1e-9);
    Indenter box = ball;
    box.shape = IndenterShape::box;
    EXPECT_NE(test::error_message([&] { skin_grid_positions(volume, roles, box, Vec3::UnitY(), 3, 2); }).find("must be a sphere"), std::string::npos);
    EXPECT_NE(test::error_message([&] { skin_grid_positions(volume, roles, ball, Vec3::UnitY(), 0, 2); }).find("0 x 2"), std::string::npos);
}

TEST(EnrichmentPlan, ConditionsAndOrientations)
{
    EnrichmentPlan plan;
    plan.positions = {{"A", Vec3(0, 0, 0)}, {"B", Vec3(10, 0, 0)}};
    plan.depths_mm = {2, 4, 6};
    plan.orientations = 4;
    plan.tilt_deg = 15;
    const auto c = plan.conditions();
    ASSERT_EQ(c.size(), 2u * 4u * 3u);
    EXPECT_EQ(c[0].position, "A");
    EXPECT_EQ(c[0].depth_mm, 2.0);
    EXPECT_EQ(c[2].depth_mm, 6.0);
    EXPECT_EQ(c[12].position, "B");
    EXPECT_LT((plan.orientation(0) - Vec3::UnitY()).norm(), 1e-15);
    for (int o = 1; o < 4; ++o) EXPECT_NEAR(std::acos(plan.orientation(o).dot(Vec3::UnitY())) * 180 / M_PI, 15.0, 1e-9);
    EXPECT_GT((plan.orientation(1) - plan.orientation(2)).norm(), 0.1);
    plan.depths_mm = {4, 2};
    EXPECT_NE(test::error_message([&] { plan.validate(); }).find("increasing"), std::string::npos);
}

struct SmallBuild {
    EnrichmentPlan plan;
    EnrichmentBuildOptions options;
    Indenter shape;
    SmallBuild()
    {
        const auto& t = levels();
        plan.positions = {{"B", t.condition.contact_mm}, {"B2", t.condition.contact_mm + Vec3(8, 0, 0)}};
        plan.direction = t.condition.direction;
        plan.depths_mm = {3.0, 6.0};
        shape.shape = IndenterShape::sphere;
        shape.radius_mm = 10.0;
        shape.path = {Vec3::Zero()};
    }
    EnrichmentDatabase build(const EnrichmentBuildOptions& o) const
    {
        const auto& t = levels();
        return build_enrichment_database(t.fine, t.coarse, t.embedding, shape, plan, o);
    }
};

TEST(EnrichmentBuild, SameDatabaseForAnyThreadOrRankCountAndResumes)
{
    const SmallBuild b;
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const EnrichmentDatabase one = b.build(b.options);
    omp_set_num_threads(2);
    const EnrichmentDatabase two = b.build(b.options);
    omp_set_num_threads(threads);
    ASSERT_EQ(one.conditions.size(), 4u);
    EXPECT_EQ(serialize_enrichment_database(one), serialize_enrichment_database(two));
    // Two ranks' parts merged = the whole.
    EnrichmentBuildOptions r0 = b.options, r1 = b.options;
    r0.ranks = r1.ranks = 2;
    r1.rank = 1;
    const auto p0 = b.build(r0), p1 = b.build(r1);
    EXPECT_EQ(p0.conditions.size(), 2u);
    EXPECT_EQ(serialize_enrichment_database(merge_enrichment_parts({p1, p0}, b.plan)), serialize_enrichment_database(one));
    EXPECT_NE(test::error_message([&] { merge_enrichment_parts({p0}, b.plan); }).find("missing"), std::string::npos);
    // Checkpoints: a second run reads them back; a corrupt one is rebuilt.
    test::TempDir dir;
    EnrichmentBuildOptions resume = b.options;
    resume.checkpoint_directory = dir / "partial";
    const auto first = b.build(resume);
    EXPECT_TRUE(std::filesystem::exists(dir / "partial" / "sequence_00001.phe"));
    std::ofstream(dir / "partial" / "sequence_00001.phe", std::ios::binary | std::ios::trunc) << "corrupt";
    const auto again = b.build(resume);
    EXPECT_EQ(serialize_enrichment_database(again), serialize_enrichment_database(one));
    EXPECT_EQ(serialize_enrichment_database(first), serialize_enrichment_database(one));
}

TEST(EnrichmentMatch, ExactConditionsRangeAndModelChecks)
{
    const SmallBuild b;
    const auto& t = levels();
    const EnrichmentDatabase db = b.build(b.options);
    // By parameters: a stored condition is found exactly and alone.
    const EnrichmentCondition query = db.conditions[3];
    const auto m = match_enrichment(db, EnrichmentMatching::parameters, 2, &query, {});
    EXPECT_EQ(m.conditions.front(), 3u);
    EXPECT_EQ(m.blend.front(), 1.0);
    EXPECT_FALSE(m.outside_range);
    // By field: the stored coarse field finds its condition.
    const std::vector<double> field(db.coarse_displacement[2].begin(), db.coarse_displacement[2].end());
    EXPECT_EQ(match_enrichment(db, EnrichmentMatching::field, 1, nullptr, field).conditions.front(), 2u);
    // Deeper than stored: flagged as extrapolation, saying how far.
    EnrichmentCondition deep = query;
    deep.depth_mm = 9.5;
    const auto out = match_enrichment(db, EnrichmentMatching::parameters, 1, &deep, {});
    EXPECT_TRUE(out.outside_range);
    EXPECT_NE(out.range_note.find("3.50 mm beyond the deepest stored (6.00 mm)"), std::string::npos) << out.range_note;
    EXPECT_NE(test::error_message([&] { match_enrichment(db, EnrichmentMatching::parameters, 1, nullptr, {}); }).find("needs the tool"),
              std::string::npos);
    // Blend size chosen by leave-one-out: an error per size, the smallest wins.
    std::vector<double> errors;
    const int k = choose_blend_size(db, t.coarse.mesh, t.embedding, t.fine.mesh.nodes, 3, &errors);
    ASSERT_EQ(errors.size(), 3u);
    EXPECT_EQ(errors[static_cast<std::size_t>(k - 1)], *std::min_element(errors.begin(), errors.end()));
    // The database must fit the model: same meshes and parameters.
    EXPECT_NO_THROW(check_database_fits(db, t.fine, t.coarse, "db"));
    LiverModel other = build_liver_model(read_label_volume(levels().dir / "ds" / "rest" / "labels.nii.gz"), phantom_label_roles(),
                                         [] { ModelParameters p; p.region = ModelRegion::liver; p.grid = {36, 27, 12}; p.coupling = {900, 500}; return p; }(), "other");
    EXPECT_NE(test::error_message([&] { check_database_fits(db, other, t.coarse, "db"); }).find("other model parameters"), std::string::npos);
    EXPECT_NE(test::error_message([&] { check_database_fits(db, t.coarse, t.coarse, "db"); }).find("another fine mesh"), std::string::npos);
}

TEST(EnrichmentMatch, SubsetSynthesisAndCondensedCoarseToFine)
{
    const SmallBuild b;
    const auto& t = levels();
    const EnrichmentDatabase db = b.build(b.options);
    // Eq. 10 on a subset of the fine nodes gives those nodes' values of the whole synthesis, bit for
    // bit, and leaves the others.
    EnrichmentCondition query = db.conditions[1];
    query.depth_mm = 4.5; // between two stored depths: a blend of two conditions
    const auto m = match_enrichment(db, EnrichmentMatching::parameters, 2, &query, {});
    ASSERT_EQ(m.conditions.size(), 2u);
    const std::vector<double> cu(db.coarse_displacement[1].begin(), db.coarse_displacement[1].end());
    const auto whole = synthesize_fine_displacement(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, blended_weights(db, m));
    std::vector<std::int32_t> subset;
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); j += 7) subset.push_back(static_cast<std::int32_t>(j));
    std::vector<double> part(whole.size(), -99.0);
    synthesize_fine_subset(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, db, m, subset, part);
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); ++j)
        for (std::size_t c = 0; c < 3; ++c) {
            if (j % 7 == 0) ASSERT_EQ(part[3 * j + c], whole[3 * j + c]) << "node " << j;
            else ASSERT_EQ(part[3 * j + c], -99.0);
        }
    const std::vector<std::int32_t> beyond{static_cast<std::int32_t>(t.fine.mesh.node_count())};
    EXPECT_NE(test::error_message([&] { synthesize_fine_subset(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, db, m, beyond, part); })
                  .find("out of range"),
              std::string::npos);
    // Coarse-to-fine on condensed contact: the synthesised nodes are those of the whole synthesis
    // from the condensed coarse model's full field, the tool pushes the liver, nothing penetrates.
    Indenter tool = b.shape;
    tool.name = "B";
    tool.path = {query.contact_mm, query.contact_mm + 4.5 * query.direction};
    CondensedCoarseToFine c2f(t.fine, t.coarse, t.embedding, db, {tool}, subset, EnrichmentMatching::parameters, 2);
    CondensedCoarseToFine::Update up;
    for (int s = 1; s <= 3; ++s) {
        EnrichmentCondition at = query;
        at.depth_mm = 1.5 * s;
        up = c2f.move_to(tool, query.contact_mm + at.depth_mm * query.direction, at);
    }
    EXPECT_GT(up.contact.active_nodes, 0);
    EXPECT_LE(up.contact.max_penetration_mm, 1e-3);
    ASSERT_EQ(up.match.conditions, m.conditions);
    const auto coarse_full = c2f.coarse_model().full_displacement_mm();
    const auto expected = synthesize_fine_displacement(t.coarse.mesh, coarse_full, t.embedding, t.fine.mesh.nodes, blended_weights(db, up.match));
    double largest = 0.0, difference = 0.0;
    for (const auto j : subset)
        for (std::size_t c = 0; c < 3; ++c) {
            const auto i = 3 * static_cast<std::size_t>(j) + c;
            largest = std::max(largest, std::abs(expected[i]));
            difference = std::max(difference, std::abs(c2f.fine_field_mm()[i] - expected[i]));
        }
    EXPECT_GT(largest, 0.5); // mm: the tool (4.5 mm of travel) moved the liver
    EXPECT_LT(difference, 1e-9);
    std::printf("condensed coarse-to-fine: largest synthesised motion %.3f mm, against the whole synthesis %.2e mm; %.3f ms per update\n",
                largest, difference, up.total_ms());
}

TEST(EnrichmentMatch, RangeIsTheStoredPositionsSpanAndDetailFallsWithDistance)
{
    // Four entry points on a 20 mm square (pressing along +y), depths 3 and 6 mm: conditions only,
    // as parameter matching reads nothing else.
    EnrichmentDatabase db;
    for (const auto& [name, x, z] : std::vector<std::tuple<std::string, double, double>>{{"P1", 0, 0}, {"P2", 20, 0}, {"P3", 0, 20}, {"P4", 20, 20}})
        for (const double depth : {3.0, 6.0}) db.conditions.push_back({name, Vec3(x, 0, z), Vec3::UnitY(), depth});
    // The square's centre is 14.1 mm from every stored position but inside their span: interpolation.
    const EnrichmentCondition centre{"", Vec3(10, 0, 10), Vec3::UnitY(), 4.0};
    const auto inside = match_enrichment(db, EnrichmentMatching::parameters, EnrichmentBlend(2, 4.0), &centre, {});
    EXPECT_FALSE(inside.outside_range) << inside.range_note;
    EXPECT_NEAR(inside.nearest_position_mm, std::sqrt(200.0), 1e-9);
    // Detail share 1 / (1 + (d/L)²) with d the nearest condition's parameter distance (14.14 + 1 mm).
    const double d = std::sqrt(200.0) + 1.0;
    EXPECT_NEAR(inside.detail, 1.0 / (1.0 + (d / 4.0) * (d / 4.0)), 1e-12);
    EXPECT_EQ(match_enrichment(db, EnrichmentMatching::parameters, 2, &centre, {}).detail, 1.0); // paper 000: ∞
    EXPECT_EQ(EnrichmentBlend(1, 0.0).detail_share(0.5), 0.0);
    EXPECT_EQ(EnrichmentBlend(1, 0.0).detail_share(0.0), 1.0); // an exact hit keeps its detail
    // 12 mm beyond the square's edge (still 12 mm from P2): extrapolation, saying how far out.
    const EnrichmentCondition beyond{"", Vec3(32, 0, 10), Vec3::UnitY(), 4.0};
    const auto out = match_enrichment(db, EnrichmentMatching::parameters, 1, &beyond, {});
    EXPECT_TRUE(out.outside_range);
    EXPECT_NE(out.range_note.find("12.0 mm outside the stored positions' span"), std::string::npos) << out.range_note;
    // Within 5 mm of the span: inside. A point on the square's own line of positions: inside.
    EXPECT_FALSE(match_enrichment(db, EnrichmentMatching::parameters, 1, &centre, {}).outside_range);
    const EnrichmentCondition near_edge{"", Vec3(24, 0, 10), Vec3::UnitY(), 4.0};
    EXPECT_FALSE(match_enrichment(db, EnrichmentMatching::parameters, 1, &near_edge, {}).outside_range);
    EXPECT_NE(test::error_message([&] { match_enrichment(db, EnrichmentMatching::parameters, EnrichmentBlend(1, -1.0), &centre, {}); })
                  .find("detail length must be ≥ 0 mm"),
              std::string::npos);
}

TEST(EnrichmentMatch, NoDetailIsTheCoarseFieldAndTheDetailLengthIsChosenLeavingPositionsOut)
{
    const SmallBuild b;
    const auto& t = levels();
    const EnrichmentDatabase db = b.build(b.options);
    EnrichmentCondition query = db.conditions[1];
    query.depth_mm = 4.5;
    const std::vector<double> cu(db.coarse_displacement[1].begin(), db.coarse_displacement[1].end());
    // Detail length 0 off a stored condition: the fine nodes get the coarse field, interpolated.
    const auto none = match_enrichment(db, EnrichmentMatching::parameters, EnrichmentBlend(2, 0.0), &query, {});
    ASSERT_EQ(none.detail, 0.0);
    EXPECT_NE(test::error_message([&] { blended_weights(db, none); }).find("needs the fine nodes' embedding"), std::string::npos);
    const auto plain = synthesize_fine_displacement(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, blended_weights(db, none, &t.embedding));
    double worst = 0.0;
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); ++j) {
        const auto u = interpolate_nodal(t.coarse.mesh, t.embedding[j], cu, 3);
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(plain[3 * j + static_cast<std::size_t>(c)] - u[static_cast<std::size_t>(c)]));
    }
    EXPECT_LT(worst, 1e-5); // mm: float32 weights
    // A share between 0 and 1: the subset synthesis still gives the whole synthesis's bits.
    const auto half = match_enrichment(db, EnrichmentMatching::parameters, EnrichmentBlend(2, 2.0), &query, {});
    EXPECT_GT(half.detail, 0.0);
    EXPECT_LT(half.detail, 1.0);
    const auto whole = synthesize_fine_displacement(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, blended_weights(db, half, &t.embedding));
    std::vector<std::int32_t> subset;
    for (std::size_t j = 0; j < t.fine.mesh.node_count(); j += 5) subset.push_back(static_cast<std::int32_t>(j));
    std::vector<double> part(whole.size(), 0.0);
    synthesize_fine_subset(t.coarse.mesh, cu, t.embedding, t.fine.mesh.nodes, db, half, subset, part);
    for (const auto j : subset)
        for (std::size_t c = 0; c < 3; ++c) ASSERT_EQ(part[3 * static_cast<std::size_t>(j) + c], whole[3 * static_cast<std::size_t>(j) + c]);
    // Leave one position out (B from B2 and back): one error per candidate length, the smallest wins.
    std::vector<std::pair<double, double>> errors;
    const double length = choose_detail_length(db, t.coarse.mesh, t.embedding, t.fine.mesh.nodes, EnrichmentMatching::parameters, 1, &errors);
    ASSERT_EQ(errors.size(), 9u);
    EXPECT_TRUE(std::isinf(errors.back().first));
    double best = errors.front().second;
    for (const auto& [l, e] : errors) {
        EXPECT_GT(e, 0.0) << l;
        best = std::min(best, e);
    }
    for (const auto& [l, e] : errors)
        if (e == best) {
            EXPECT_EQ(l, length);
        }
    std::printf("detail length %.0f mm; leave-one-position-out error: no detail %.4f mm, all detail %.4f mm\n", length, errors.front().second,
                errors.back().second);
    // One position only: nothing to leave out, paper 000's behaviour.
    SmallBuild one = b;
    one.plan.positions.resize(1);
    EXPECT_TRUE(std::isinf(choose_detail_length(one.build(one.options), t.coarse.mesh, t.embedding, t.fine.mesh.nodes, EnrichmentMatching::field, 1)));
}

TEST(LiverModel, TransferDisplacementCarriesALinearFieldExactly)
{
    const auto& t = levels();
    // A linear field on the coarse nodes arrives exactly at the fine nodes inside the coarse mesh.
    const Eigen::Matrix3d a = (Eigen::Matrix3d() << 0.01, -0.02, 0.003, 0.0, 0.015, -0.01, 0.02, 0.004, -0.005).finished();
    const Vec3 shift(0.3, -0.2, 0.1);
    std::vector<double> coarse_u(3 * t.coarse.mesh.node_count());
    for (std::size_t n = 0; n < t.coarse.mesh.node_count(); ++n) {
        const Vec3 u = a * t.coarse.mesh.nodes[n] + shift;
        for (int c = 0; c < 3; ++c) coarse_u[3 * n + static_cast<std::size_t>(c)] = u[c];
    }
    const auto fine_u = transfer_displacement(t.coarse, coarse_u, t.fine);
    ASSERT_EQ(fine_u.size(), 3 * t.fine.mesh.node_count());
    std::size_t inside = 0;
    for (std::size_t n = 0; n < t.fine.mesh.node_count(); ++n) {
        if (!t.embedding[n].inside) continue;
        ++inside;
        const Vec3 expected = a * t.fine.mesh.nodes[n] + shift;
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(fine_u[3 * n + static_cast<std::size_t>(c)], expected[c], 1e-9) << "node " << n;
    }
    EXPECT_GT(inside, t.fine.mesh.node_count() / 2);
    EXPECT_NE(test::error_message([&] { transfer_displacement(t.coarse, {1.0, 2.0}, t.fine); }).find("2 values for"), std::string::npos);
}

} // namespace
} // namespace physreg
