// Detail enrichment (paper 000 eqs. 9–10): exact reproduction of a training condition and the
// database file's round trip and corruption checks.
#include "test_support.hpp"

#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/mesh/point_location.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/registration/enrichment.hpp"
#include "physreg/registration/estimation.hpp"

#include <gtest/gtest.h>

#include <fstream>

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
        generate_phantom_dataset(PhantomSpec::preset_spec("small"), dir / "ds", false, {});
        const PhantomDataset d = read_phantom_dataset(dir / "ds");
        const LabelVolume labels = read_label_volume(d.path(d.state("rest").files.at("labels")));
        ModelParameters p;
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
