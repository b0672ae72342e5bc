// The phantom dataset (issue 4): files readable by ITK, geometry, landmarks, ground-truth support
// and contact, determinism, bad input; the ground-truth solver against an analytical answer.
#include "physreg/core/error.hpp"
#include "physreg/field/image_warping.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/io/png.hpp"
#include "physreg/io/vtu.hpp"
#include "physreg/mesh/faces.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/phantom/landmark_picking.hpp"
#include "physreg/phantom/partial_surface.hpp"
#include "mechanics_fixtures.hpp"
#include "test_support.hpp"

#include <fstream>
#include <iterator>
#include <numeric>

namespace physreg {
namespace {
namespace fs = std::filesystem;

// One small dataset shared by the tests of this file (2 s to make).
class PhantomSmall : public ::testing::Test {
protected:
    static void SetUpTestSuite()
    {
        directory = new test::TempDir();
        generate_phantom_dataset(PhantomSpec::preset_spec("small"), directory->path() / "ds", false, {});
    }
    static void TearDownTestSuite()
    {
        delete directory;
        directory = nullptr;
    }
    static fs::path root() { return directory->path() / "ds"; }
    static test::TempDir* directory;
};
test::TempDir* PhantomSmall::directory = nullptr;

std::string file_bytes(const fs::path& path)
{
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

bool same_geometry(const ImageGeometry& a, const ImageGeometry& b)
{
    return a.size == b.size && (a.origin - b.origin).norm() < 1e-4 && (a.spacing - b.spacing).norm() < 1e-6 &&
           (a.direction - b.direction).norm() < 1e-6;
}

TEST_F(PhantomSmall, EveryFileOpensAndMatchesTheRestGeometry)
{
    const PhantomDataset d = read_phantom_dataset(root());
    ASSERT_EQ(d.states.size(), 7u); // rest, A–E, insufflation
    EXPECT_EQ(d.states[1].name, "A");
    EXPECT_EQ(d.states.back().kind, "insufflation");
    const LabelVolume rest = read_label_volume(d.path(d.state("rest").files.at("labels")));
    const auto counts = count_labels(rest);
    for (int label = 0; label <= 6; ++label) EXPECT_GT(counts.count(label), 0u) << "label " << label << " missing";
    for (const auto& s : d.states) {
        SCOPED_TRACE(s.name);
        const LabelVolume labels = read_label_volume(d.path(s.files.at("labels")));
        EXPECT_TRUE(same_geometry(labels.geometry, rest.geometry));
        const ScalarImage image = read_scalar_image(d.path(s.files.at("intensity")));
        EXPECT_TRUE(same_geometry(image.geometry, rest.geometry));
        const LandmarkSet landmarks = read_landmarks(d.path(s.files.at("landmarks")));
        ASSERT_EQ(landmarks.size(), 25u);
        EXPECT_EQ(std::count_if(landmarks.begin(), landmarks.end(), [](const Landmark& l) { return l.type == LandmarkType::surface; }), 11);
        EXPECT_EQ(read_landmarks(d.path(s.files.at("landmarks_noisy"))).size(), 25u);
        MeshData data;
        const VolumeMesh mesh = read_vtu(d.path(s.files.at("mesh")), &data);
        ASSERT_NE(data.find_point("displacement"), nullptr);
        const RgbImage picture = read_png(d.path(s.files.at("picture")));
        EXPECT_GT(picture.width, 300);
        if (s.kind == "rest") continue;
        const DisplacementField forward = read_displacement_field(d.path(s.files.at("displacement")));
        const DisplacementField inverse = read_displacement_field(d.path(s.files.at("inverse_displacement")));
        EXPECT_TRUE(same_geometry(forward.geometry, rest.geometry));
        EXPECT_TRUE(same_geometry(inverse.geometry, rest.geometry));
        EXPECT_GT(s.max_displacement_mm, 1.0);
        // The deformed liver keeps roughly its volume (ν = 0.49), and lesions survive the warp.
        const auto deformed_counts = count_labels(labels);
        EXPECT_NEAR(double(deformed_counts.at(2)), double(counts.at(2)), 0.08 * double(counts.at(2)));
        ASSERT_EQ(s.surfaces.size(), 2u);
        const auto cloud50 = read_point_cloud_csv(d.path(s.surfaces.at(50).second));
        const auto cloud10 = read_point_cloud_csv(d.path(s.surfaces.at(10).second));
        EXPECT_GT(cloud50.points.size(), 3 * cloud10.points.size());
    }
}

TEST_F(PhantomSmall, LandmarksSitOnTheSurfaceOrInsideTheLiver)
{
    const PhantomDataset d = read_phantom_dataset(root());
    const LabelVolume rest = read_label_volume(d.path(d.state("rest").files.at("labels")));
    const auto& g = rest.geometry;
    const double voxel = g.spacing.maxCoeff();
    auto label_at = [&](const Vec3& p) -> int {
        const Vec3 index = g.physical_to_index(p);
        return rest.at(std::lround(index[0]), std::lround(index[1]), std::lround(index[2]));
    };
    const auto roles = d.roles;
    for (const auto& l : read_landmarks(d.path(d.state("rest").files.at("landmarks")))) {
        SCOPED_TRACE(l.name);
        // Sample a ball of one voxel radius around the landmark.
        int liver = 0, other = 0, lesion = 0, non_lesion = 0;
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const Vec3 offset = 0.6 * voxel * Vec3(dx, dy, dz);
                    if (offset.norm() > voxel) continue;
                    const int label = label_at(l.position + offset);
                    roles.is_liver_tissue(label) ? ++liver : ++other;
                    roles.lesion.count(label) ? ++lesion : ++non_lesion;
                }
        if (l.type == LandmarkType::surface) {
            EXPECT_GT(liver, 0);  // within one voxel of liver ...
            EXPECT_GT(other, 0);  // ... and of outside: on the surface
        } else {
            EXPECT_TRUE(roles.is_liver_tissue(label_at(l.position - 0.25 * voxel * Vec3::UnitY())) ||
                        roles.is_liver_tissue(label_at(l.position + 0.25 * voxel * Vec3::UnitY())));
            EXPECT_EQ(other, 0) << "internal landmark touches the outside";
        }
        if (l.type == LandmarkType::tumour) {
            EXPECT_GT(lesion, 0);
            EXPECT_GT(non_lesion, 0);
        }
    }
}

TEST_F(PhantomSmall, GroundTruthIsZeroOnTheSupportAndTheToolDoesNotPenetrate)
{
    const PhantomDataset d = read_phantom_dataset(root());
    std::ifstream in(root() / "manifest.json");
    const std::string manifest((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const auto& s : d.states) {
        if (s.kind == "rest") continue;
        SCOPED_TRACE(s.name);
        MeshData data;
        const VolumeMesh mesh = read_vtu(d.path(s.files.at("mesh")), &data);
        const auto& u = data.find_point("displacement")->values;
        // The support: nodes of boundary faces whose outward normal points posterior.
        int supported = 0;
        for (const auto& f : match_faces(mesh)) {
            if (f.neighbour >= 0) continue;
            const Vec3 n = (mesh.nodes[f.nodes[2]] - mesh.nodes[f.nodes[0]]).cross(mesh.nodes[f.nodes[3]] - mesh.nodes[f.nodes[1]]).normalized();
            if (n.y() <= 0.5) continue;
            for (int a = 0; a < 4; ++a) {
                const auto q = 3 * static_cast<std::size_t>(f.nodes[a]);
                EXPECT_EQ(Vec3(u[q], u[q + 1], u[q + 2]).norm(), 0.0);
                ++supported;
            }
        }
        EXPECT_GT(supported, 50);
    }
    // Contact: no node ends up inside a tool (node-on-surface projection; tolerance 1e-6 mm).
    EXPECT_EQ(manifest.find("\"max_node_penetration_mm\": 0.1"), std::string::npos);
    for (const auto& s : d.states) {
        if (s.kind != "compression") continue;
        MeshData data;
        const VolumeMesh mesh = read_vtu(d.path(s.files.at("mesh")), &data);
        const auto& u = data.find_point("displacement")->values;
        // The tool of the small preset: a sphere; its final centre from the manifest.
        const double r = PhantomSpec::preset_spec("small").tool.radius_mm;
        const auto key = "\"name\": \"" + s.name + "\"";
        const auto at = manifest.find(key);
        ASSERT_NE(at, std::string::npos);
        const auto final_at = manifest.find("\"final_position_mm\": [", at);
        ASSERT_NE(final_at, std::string::npos);
        Vec3 centre;
        std::sscanf(manifest.c_str() + final_at + std::string("\"final_position_mm\": [").size(), " %lf , %lf , %lf", &centre[0], &centre[1], &centre[2]);
        // Contact holds the boundary nodes exactly on the tool; between them a face may cut the tool
        // by at most the sag of a chord of one cell, h²/(8r) (the contact tolerance of node-to-surface contact).
        std::vector<char> boundary(mesh.node_count(), 0);
        for (const auto& f : match_faces(mesh))
            if (f.neighbour < 0)
                for (int a = 0; a < f.node_count(); ++a) boundary[static_cast<std::size_t>(f.nodes[a])] = 1;
        const double h = mesh.grid->cell_size.maxCoeff(), sag = h * h / (8 * r);
        double deepest = 0.0, deepest_interior = 0.0, closest = 1e9;
        for (std::size_t n = 0; n < mesh.node_count(); ++n) {
            const Vec3 x = mesh.nodes[n] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]);
            const double distance = (x - centre).norm();
            (boundary[n] ? deepest : deepest_interior) = std::max(boundary[n] ? deepest : deepest_interior, r - distance);
            if (boundary[n]) closest = std::min(closest, distance);
        }
        EXPECT_LE(deepest, 1e-6) << s.name << ": a surface node is inside the tool";
        EXPECT_LE(deepest_interior, sag) << s.name << ": the surface cuts the tool deeper than the contact tolerance";
        EXPECT_NEAR(closest, r, 1e-6) << s.name << ": the tool touches the deformed surface";
    }
}

TEST_F(PhantomSmall, SameSeedGivesIdenticalFilesAndAnotherSeedChangesTheNoise)
{
    test::TempDir again;
    generate_phantom_dataset(PhantomSpec::preset_spec("small"), again / "ds", false, {});
    std::size_t compared = 0;
    for (const auto& entry : fs::recursive_directory_iterator(root())) {
        if (!entry.is_regular_file()) continue;
        const fs::path relative = fs::relative(entry.path(), root());
        ASSERT_TRUE(fs::exists(again / "ds" / relative)) << relative;
        EXPECT_EQ(file_bytes(entry.path()), file_bytes(again / "ds" / relative)) << relative << " differs";
        ++compared;
    }
    EXPECT_GT(compared, 60u);
    PhantomSpec other = PhantomSpec::preset_spec("small");
    other.seed = 2;
    other.compressions = {};
    other.depths_mm = {5};
    generate_phantom_dataset(other, again / "seed2", false, {});
    EXPECT_NE(file_bytes(root() / "rest/landmarks_noisy.csv"), file_bytes(again / "seed2/rest/landmarks_noisy.csv"));
    EXPECT_EQ(file_bytes(root() / "rest/landmarks.csv"), file_bytes(again / "seed2/rest/landmarks.csv"));
    EXPECT_EQ(file_bytes(root() / "rest/labels.nii.gz"), file_bytes(again / "seed2/rest/labels.nii.gz"));
    EXPECT_NE(file_bytes(root() / "rest/intensity.nii.gz"), file_bytes(again / "seed2/rest/intensity.nii.gz"));
}

TEST(PhantomDataset, BadInputIsRefusedAndLeavesNothing)
{
    test::TempDir dir;
    // Unknown preset.
    EXPECT_NE(test::error_message([] { PhantomSpec::preset_spec("cirs999"); }).find("unknown preset 'cirs999'"), std::string::npos);
    // A label map without a liver label.
    const LabelVolume no_liver = test::make_volume({20, 20, 20}, [](int i, int, int) { return i < 10 ? 1 : 5; }, Vec3::Constant(2.0));
    write_label_volume(dir / "no_liver.nii.gz", no_liver);
    PhantomSpec spec = PhantomSpec::preset_spec("small");
    spec.preset = "from-labels";
    spec.labels_file = dir / "no_liver.nii.gz";
    const std::string message = test::error_message([&] { generate_phantom_dataset(spec, dir / "out1", false, {}); });
    EXPECT_NE(message.find("no liver label"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(dir / "out1"));
    // A compression outside the body.
    PhantomSpec outside = PhantomSpec::preset_spec("small");
    CompressionSpec c;
    c.name = "X";
    c.x_mm = 500;
    c.z_mm = 0;
    c.depth_mm = 5;
    c.tool = outside.tool;
    outside.compressions = {c};
    const std::string outside_message = test::error_message([&] { generate_phantom_dataset(outside, dir / "out2", false, {}); });
    EXPECT_NE(outside_message.find("outside the body"), std::string::npos) << outside_message;
    EXPECT_FALSE(fs::exists(dir / "out2"));
    // A tool narrower than the cells would slip between nodes.
    PhantomSpec narrow = PhantomSpec::preset_spec("small");
    narrow.tool.radius_mm = 2.0;
    const std::string narrow_message = test::error_message([&] { generate_phantom_dataset(narrow, dir / "out4", false, {}); });
    EXPECT_NE(narrow_message.find("narrower than the ground-truth cells"), std::string::npos) << narrow_message;
    EXPECT_FALSE(fs::exists(dir / "out4"));
    // A depth beyond most of the organ's thickness along the tool's line.
    PhantomSpec deep = PhantomSpec::preset_spec("small");
    CompressionSpec left = c;
    left.name = "L";
    left.x_mm = 60; // the left lobe, ≈ 48 mm thick
    left.z_mm = 8;
    left.depth_mm = 40;
    deep.compressions = {left};
    const std::string deep_message = test::error_message([&] { generate_phantom_dataset(deep, dir / "out3", false, {}); });
    EXPECT_NE(deep_message.find("compression L: depth 40.0 mm exceeds 60 % of the organs' thickness"), std::string::npos) << deep_message;
    EXPECT_FALSE(fs::exists(dir / "out3"));
    // A tool that slips between the coarse surface nodes instead of pressing.
    deep.compressions = {};
    deep.tool.radius_mm = 7.0;
    deep.depths_mm = {25};
    const std::string slipped = test::error_message([&] { generate_phantom_dataset(deep, dir / "out3", false, {}); });
    EXPECT_NE(slipped.find("the tool slipped past the surface nodes"), std::string::npos) << slipped;
    EXPECT_FALSE(fs::exists(dir / "out3"));
    EXPECT_TRUE(dir.files().size() == 1u) << "only no_liver.nii.gz should remain"; // no staging folders left
    // An existing non-empty output is refused before any work.
    fs::create_directories(dir / "full");
    std::ofstream(dir / "full" / "keep.txt") << "x";
    EXPECT_NE(test::error_message([&] { generate_phantom_dataset(PhantomSpec::preset_spec("small"), dir / "full", false, {}); }).find("not empty"),
              std::string::npos);
    EXPECT_TRUE(fs::exists(dir / "full" / "keep.txt"));
    // Label roles.
    EXPECT_NE(test::error_message([] { parse_label_roles("liver=1;lesion=1", "--label-roles"); }).find("two roles"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_label_roles("vessel=4", "--label-roles"); }).find("no liver"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_label_roles("spleen=4", "--label-roles"); }).find("unknown role"), std::string::npos);
}

// The ground-truth solver on a case with a known answer: a Neo-Hookean block between a rigid
// plane tool and a frictionless base, symmetry planes on two sides: exact uniaxial compression.
TEST(PhantomGroundTruth, FrictionlessPlaneCompressionMatchesTheAnalyticalNeoHookeanSolution)
{
    const double h = 2.0, side = 12.0;
    const VolumeMesh mesh = test::block_mesh(6, 6, 6, h); // [0,12]³
    TissueTable tissues = test::one_tissue(2e5, 0.49);
    const TledModel model(mesh, tissues, TledOptions{});
    Loads loads;
    loads.constraints.push_back({"base", test::nodes_at(mesh, 1, side), {false, true, false}, Vec3::Zero()}); // y = 12 held in y
    loads.constraints.push_back({"x-symmetry", test::nodes_at(mesh, 0, 0.0), {true, false, false}, Vec3::Zero()});
    loads.constraints.push_back({"z-symmetry", test::nodes_at(mesh, 2, 0.0), {false, false, true}, Vec3::Zero()});
    Indenter plate;
    plate.name = "plate";
    plate.shape = IndenterShape::plane;
    plate.axis = Vec3::UnitY(); // tissue on the +y side
    const double depth = 1.8;   // 15 % compression
    plate.path = {Vec3(6, 0, 6), Vec3(6, depth, 6)};
    loads.indenters.push_back(plate);
    std::vector<std::int32_t> surface(mesh.node_count());
    std::iota(surface.begin(), surface.end(), 0);
    const GroundTruthSolution solution =
        solve_ground_truth(model, loads, PhantomSpec::tight_equilibrium(), 3, false, surface, "plane compression");
    const double stretch = (side - depth) / side;
    const auto [lateral, nominal_stress_mpa] = test::neo_hookean_uniaxial(stretch, model.materials().front());
    // Every node on the uniaxial map: y' = 12 − λ(12 − y), x' = λ_lat x, z' = λ_lat z.
    double worst = 0.0;
    for (std::size_t n = 0; n < mesh.node_count(); ++n) {
        const Vec3& X = mesh.nodes[n];
        const Vec3 expected(lateral * X.x(), side - stretch * (side - X.y()), lateral * X.z());
        const Vec3 got = X + Vec3(solution.displacement_mm[3 * n], solution.displacement_mm[3 * n + 1], solution.displacement_mm[3 * n + 2]);
        worst = std::max(worst, (got - expected).norm());
    }
    EXPECT_LT(worst, 2e-3) << "lateral stretch " << lateral; // mm, against a 1.8 mm compression
    EXPECT_LE(solution.max_node_penetration_mm, 1e-9);
    (void)nominal_stress_mpa;
}

TEST(PhantomAnatomy, PresetMatchesThePhantomsMeasuredSize)
{
    const LabelVolume v = make_cirs057a_phantom(2.0);
    Vec3 lo = Vec3::Constant(1e9), hi = Vec3::Constant(-1e9), body_lo = lo, body_hi = hi;
    const auto& g = v.geometry;
    std::int64_t lesion = 0, vessel = 0;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto l = v.at(i, j, k);
                const Vec3 p = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                if (l == 0) continue;
                body_lo = body_lo.cwiseMin(p), body_hi = body_hi.cwiseMax(p);
                if (l >= 2 && l <= 4) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
                lesion += l == 3, vessel += l == 4;
            }
    const Vec3 liver = hi - lo + Vec3::Constant(2.0), body = body_hi - body_lo + Vec3::Constant(2.0);
    EXPECT_NEAR(body.x(), 270, 6);
    EXPECT_NEAR(body.y(), 185, 6); // 200 mm superellipse cut by the flat base
    EXPECT_NEAR(body.z(), 130, 4);
    EXPECT_NEAR(liver.x(), 184, 10);
    EXPECT_NEAR(liver.y(), 142, 15);
    EXPECT_NEAR(liver.z(), 89, 8);
    // Lesions 14, 14, 9, 8, 5, 5 mm: Σ of sphere volumes ≈ 3.6 ml; vessels a few ml.
    EXPECT_NEAR(lesion * 8.0, 3600, 900);
    EXPECT_GT(vessel * 8.0, 2000);
}

TEST(ImageWarping, InverseMapOfAnAffineDeformationIsExact)
{
    // A block mesh stretched by 10 % in x about x = 0: the inverse map is x ↦ x / 1.1.
    const VolumeMesh mesh = test::block_mesh(5, 5, 5, 2.0);
    std::vector<double> u(3 * mesh.node_count(), 0.0);
    for (std::size_t n = 0; n < mesh.node_count(); ++n) u[3 * n] = 0.1 * mesh.nodes[n].x();
    ImageGeometry g;
    g.size = {16, 12, 12};
    g.spacing = Vec3::Constant(1.0);
    g.origin = Vec3(0.5, 0.5, 0.5);
    const InverseMap map = rasterize_inverse_map(mesh, u, g, 0.0);
    int covered = 0;
    for (std::int64_t k = 0; k < g.size[2]; ++k)
        for (std::int64_t j = 0; j < g.size[1]; ++j)
            for (std::int64_t i = 0; i < g.size[0]; ++i) {
                const auto v = static_cast<std::size_t>(g.linear_index(i, j, k));
                const Vec3 x = g.index_to_physical(Vec3(double(i), double(j), double(k)));
                const bool inside = x.x() <= 11.0 && x.y() <= 10.0 && x.z() <= 10.0;
                EXPECT_EQ(map.coverage[v] == 1, inside);
                if (!inside) continue;
                ++covered;
                EXPECT_NEAR(map.field.components[3 * v], x.x() / 1.1 - x.x(), 1e-5);
                EXPECT_NEAR(map.field.components[3 * v + 1], 0.0, 1e-6);
            }
    EXPECT_EQ(covered, 11 * 10 * 10);
}

} // namespace
} // namespace physreg
