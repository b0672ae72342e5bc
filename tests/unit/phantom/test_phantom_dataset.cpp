// SPDX-License-Identifier: GPL-3.0-or-later
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
#include "physreg/phantom/ground_truth.hpp"

#include <nlohmann/json.hpp>
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

// One small dataset shared by the tests of this file (the `small` preset: five compressions of the
// body ground truth).
class PhantomSmall : public ::testing::Test {
protected:
    static void SetUpTestSuite()
    {
        directory = new test::TempDir();
        PhantomSpec spec = PhantomSpec::preset_spec("small");
        spec.depths_mm = {10, 12}; // compressions A, B (each test process makes its own copy)
        generate_phantom_dataset(spec, directory->path() / "ds", false, {});
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
    ASSERT_EQ(d.states.size(), 4u); // rest, A, B, insufflation
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

TEST_F(PhantomSmall, GroundTruthHoldsItsSupportsAndTheToolPressesTheSkin)
{
    const PhantomDataset d = read_phantom_dataset(root());
    std::ifstream in(root() / "manifest.json");
    const auto manifest = nlohmann::json::parse(in);
    const auto& gt = manifest.at("ground_truth");
    // What the ground truth is, for reports: not the registration models' family.
    EXPECT_NE(gt.at("element").get<std::string>().find("tetrahedra"), std::string::npos);
    EXPECT_NE(gt.at("material_law").get<std::string>().find("Mooney-Rivlin"), std::string::npos);
    EXPECT_NE(gt.at("contact").at("organs_gel").get<std::string>().find("tied"), std::string::npos);
    const auto simulated = gt.at("simulated_tissues").get<std::vector<std::string>>();
    EXPECT_NE(std::find(simulated.begin(), simulated.end(), "body"), simulated.end()) << "the gel body is simulated";
    for (const auto& t : gt.at("tissues")) {
        EXPECT_GE(t.at("poisson_ratio").get<double>(), 0.49);
        EXPECT_GT(t.at("mooney_rivlin_c01_pa").get<double>(), 0.0);
    }
    EXPECT_TRUE(gt.at("calculix_validation").contains("run"));
    if (gt.at("calculix_validation").at("run").get<bool>()) {
        EXPECT_LT(gt.at("calculix_validation").at("relative_rms").get<double>(), 0.01);
    }
    EXPECT_GT(gt.at("models").at("body").at("quality").at("min_dihedral_deg").get<double>(), 0.5);
    for (const auto& s : d.states) {
        if (s.kind == "rest") continue;
        SCOPED_TRACE(s.name);
        MeshData data;
        const VolumeMesh mesh = read_vtu(d.path(s.files.at("mesh")), &data);
        const auto& u = data.find_point("displacement")->values;
        ASSERT_EQ(mesh.cell_type, CellType::tetrahedron);
        double deepest = -1e300;
        for (const auto& x : mesh.nodes) deepest = std::max(deepest, x.y());
        // Compressions (body model): the flat base stays on the table (u_y = 0); insufflation
        // (organs alone): the posterior organ surface is fixed.
        int held = 0;
        for (const auto& f : boundary_faces(mesh)) {
            // The base: nodes of faces facing posterior within half a facet of the deepest skin.
            const double half_facet = 0.5 * PhantomSpec::preset_spec("small").ground_truth_mesh.facet_mm;
            const bool base = s.kind == "compression" && f.normal.y() > 0.9;
            const bool posterior = s.kind == "insufflation" && f.normal.y() > 0.5;
            if (!base && !posterior) continue;
            for (int a = 0; a < f.count; ++a) {
                if (base && mesh.nodes[f.nodes[a]].y() <= deepest - half_facet) continue;
                const auto q = 3 * static_cast<std::size_t>(f.nodes[a]);
                EXPECT_EQ(u[q + 1], 0.0);
                if (posterior) {
                    EXPECT_EQ(Vec3(u[q], u[q + 1], u[q + 2]).norm(), 0.0);
                }
                ++held;
            }
        }
        EXPECT_GT(held, 20);
        if (s.kind != "compression") continue;
        // Contact: no skin node inside the tool beyond the augmented-Lagrangian tolerance, and the
        // tool touches the deformed skin.
        ASSERT_TRUE(s.tool.has_value());
        const Vec3 centre = s.tool->path.back();
        const double r = s.tool->radius_mm;
        double closest = 1e9;
        for (const auto& f : boundary_faces(mesh))
            for (int a = 0; a < f.count; ++a) {
                const auto n = static_cast<std::size_t>(f.nodes[a]);
                closest = std::min(closest, (mesh.nodes[n] + Vec3(u[3 * n], u[3 * n + 1], u[3 * n + 2]) - centre).norm());
            }
        EXPECT_GE(closest, r - 1.01 * ground_truth_penetration_tolerance_mm) << "a skin node is inside the tool";
        EXPECT_LE(closest, r + 0.2) << "the tool does not touch the skin";
    }
}

TEST(PhantomDataset, SameSeedGivesIdenticalFilesAndAnotherSeedChangesMaterialsAndNoise)
{
    test::TempDir dir;
    PhantomSpec spec = PhantomSpec::preset_spec("small");
    spec.depths_mm = {8};        // compression A only
    spec.surface_percentages = {30};
    spec.calculix_validation = false;
    // Coarser ground-truth tetrahedra than the preset's: determinism does not depend on the mesh
    // size, and three datasets are made here.
    spec.ground_truth_mesh.organ_cell_mm = 10.0;
    spec.ground_truth_mesh.kidney_cell_mm = 14.0;
    spec.ground_truth_mesh.body_cell_mm = 24.0;
    generate_phantom_dataset(spec, dir / "one", false, {});
    generate_phantom_dataset(spec, dir / "two", false, {});
    std::size_t compared = 0;
    for (const auto& entry : fs::recursive_directory_iterator(dir / "one")) {
        if (!entry.is_regular_file()) continue;
        const fs::path relative = fs::relative(entry.path(), dir / "one");
        ASSERT_TRUE(fs::exists(dir / "two" / relative)) << relative;
        EXPECT_EQ(file_bytes(entry.path()), file_bytes(dir / "two" / relative)) << relative << " differs";
        ++compared;
    }
    EXPECT_GT(compared, 25u);
    PhantomSpec other = spec;
    other.seed = 2;
    generate_phantom_dataset(other, dir / "seed2", false, {});
    EXPECT_NE(file_bytes(dir / "one/rest/landmarks_noisy.csv"), file_bytes(dir / "seed2/rest/landmarks_noisy.csv"));
    EXPECT_EQ(file_bytes(dir / "one/rest/landmarks.csv"), file_bytes(dir / "seed2/rest/landmarks.csv"));
    EXPECT_EQ(file_bytes(dir / "one/rest/labels.nii.gz"), file_bytes(dir / "seed2/rest/labels.nii.gz"));
    EXPECT_NE(file_bytes(dir / "one/rest/intensity.nii.gz"), file_bytes(dir / "seed2/rest/intensity.nii.gz"));
    // The ground truth's materials are drawn from the seed (unknown to the registration models).
    EXPECT_NE(file_bytes(dir / "one/ground_truth_tissues.yaml"), file_bytes(dir / "seed2/ground_truth_tissues.yaml"));
    EXPECT_NE(file_bytes(dir / "one/states/A/landmarks.csv"), file_bytes(dir / "seed2/states/A/landmarks.csv"));
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
    EXPECT_NE(narrow_message.find("narrower than two surface facets"), std::string::npos) << narrow_message;
    EXPECT_FALSE(fs::exists(dir / "out4"));
    // Seeds out of range, too many depths.
    PhantomSpec seedless = PhantomSpec::preset_spec("small");
    seedless.seed = 0;
    EXPECT_NE(test::error_message([&] { generate_phantom_dataset(seedless, dir / "out3", false, {}); }).find("--seed 0 outside"), std::string::npos);
    seedless.seed = 1ull << 33;
    EXPECT_NE(test::error_message([&] { seedless.validate(); }).find("outside 1 … 4294967295"), std::string::npos);
    PhantomSpec six = PhantomSpec::preset_spec("small");
    six.depths_mm = {5, 5, 5, 5, 5, 5};
    EXPECT_NE(test::error_message([&] { six.validate(); }).find("6 depths given"), std::string::npos);
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

// Issue 46 item 6: the organs alone may be held elsewhere than posterior, so that a registration
// which assumes the generator's convention meets a truth that does not share it.
TEST(PhantomDataset, OrgansAloneAreHeldWhereAsked)
{
    EXPECT_EQ(parse_organ_support("inferior", "--organ-support").direction, Vec3(0, 0, -1));
    EXPECT_EQ(parse_organ_support("posterior", "--organ-support").direction, Vec3(0, 1, 0));
    const OrganSupport tilted = parse_organ_support("1,0,-1", "--organ-support");
    EXPECT_EQ(tilted.direction, Vec3(1, 0, -1));
    EXPECT_NE(tilted.name.find("direction"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_organ_support("sideways", "--organ-support"); }).find("--organ-support: 'sideways' is neither"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_organ_support("0,0,0", "--organ-support"); }).find("non-zero"), std::string::npos);
    EXPECT_NE(test::error_message([] { parse_organ_support("1,nan,0", "--organ-support"); }).find("neither"), std::string::npos);

    // A 40 × 30 × 30 mm block of liver (label 2), 2 mm voxels, no body label: the organs alone.
    LabelVolume labels;
    labels.geometry.size = {24, 19, 19};
    labels.geometry.spacing = Vec3(2, 2, 2);
    labels.labels.assign(static_cast<std::size_t>(labels.geometry.voxel_count()), 0);
    for (std::int64_t k = 2; k < 17; ++k)
        for (std::int64_t j = 2; j < 17; ++j)
            for (std::int64_t i = 2; i < 22; ++i) labels.labels[static_cast<std::size_t>(labels.geometry.linear_index(i, j, k))] = 2;
    LabelRoles roles;
    roles.liver = {2};
    nlohmann::json ranges;
    const TissueTable tissues = draw_ground_truth_tissues(MaterialSet::healthy, roles, {0, 2}, 5, ranges);
    GroundTruthMeshing meshing = PhantomSpec::preset_spec("small").ground_truth_mesh;
    for (const auto& [name, direction] : std::vector<std::pair<std::string, Vec3>>{{"inferior", Vec3(0, 0, -1)}, {"right", Vec3(-1, 0, 0)}}) {
        SCOPED_TRACE(name);
        const GroundTruthModel m = build_body_model(labels, roles, tissues, meshing, 3, parse_organ_support(name, "--organ-support"));
        ASSERT_EQ(m.name, "organs");
        ASSERT_EQ(m.supports.constraints.size(), 1u);
        EXPECT_EQ(m.supports.constraints[0].name, name + "_support");
        EXPECT_NE(m.support_description.find("facing " + name), std::string::npos) << m.support_description;
        // Every held node lies on the block's face that looks that way (within a ground-truth cell:
        // the mesher rounds the block's edges), none on the other side of the 30 mm thick block.
        double extreme = -1e300;
        for (const auto& x : m.mesh.nodes) extreme = std::max(extreme, x.dot(direction));
        ASSERT_GT(m.supports.constraints[0].nodes.size(), 10u);
        for (const auto n : m.supports.constraints[0].nodes)
            EXPECT_GT(m.mesh.nodes[static_cast<std::size_t>(n)].dot(direction), extreme - meshing.organ_cell_mm);
    }
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

namespace physreg {

TEST(PartialSurface, SparseCloudCoversTheSurfaceButItsBackAndWhatIsHidden)
{
    // A 40 × 20 × 20 mm block of hexahedra (label 1): its boundary, a "tool" hiding x < 8 mm.
    const VolumeMesh mesh = test::block_mesh(8, 4, 4, 5.0);
    const BoundarySurface boundary = liver_boundary(mesh, [](std::int32_t l) { return l != 0; }, std::nullopt);
    const std::vector<double> u(3 * mesh.node_count(), 0.0);
    double covered = 0.0;
    const auto hidden = [](const Vec3& x) { return x.x() < 8.0; };
    const LabelledPointCloud cloud = sparse_surface_cloud(mesh, u, boundary, 0.55, 400, hidden, 0.0, 7, &covered);
    ASSERT_EQ(cloud.points.size(), 400u);
    // Total area 4 (40·20) + 2 (20·20) = 4000 mm²; hidden: the x = 0 face and 5–10 mm strips of four
    // faces (≈ 1000 mm²); then the back (≈ 650 mm² left of the y = 20 face) is dropped first.
    EXPECT_GT(covered, 0.5);
    EXPECT_LE(covered, 0.55 + 1e-9);
    int back = 0;
    for (std::size_t q = 0; q < cloud.points.size(); ++q) {
        const Vec3& p = cloud.points[q];
        EXPECT_GE(p.x(), 5.0 - 1e-9) << "a point under the hidden strip";
        EXPECT_EQ(cloud.labels[q], feature_none);
        EXPECT_NEAR(cloud.normals[q].norm(), 1.0, 1e-9);
        // On the surface of the block (noise 0).
        const double inside = std::min({p.x(), 40 - p.x(), p.y(), 20 - p.y(), p.z(), 20 - p.z()});
        EXPECT_NEAR(inside, 0.0, 1e-9);
        back += std::abs(p.y() - 20.0) < 1e-9;
    }
    EXPECT_EQ(back, 0) << "the posterior face (y = 20 mm, normal +y) goes first";
    EXPECT_NE(test::error_message([&] { sparse_surface_cloud(mesh, u, boundary, 0.0, 400, hidden, 0.0, 7); }).find("coverage"), std::string::npos);
    EXPECT_NE(test::error_message([&] { sparse_surface_cloud(mesh, u, boundary, 0.9, 2, hidden, 0.0, 7); }).find("at least 3"), std::string::npos);
}

} // namespace physreg

namespace physreg {

// CGAL's initial points come from random rays: with seed 9 they found one small structure of the
// small phantom's organs (505 tetrahedra, 7 % of the labels' volume) and the landmarks then lay
// 94 mm outside the ground truth (found by scripts/study_unaligned_pairs.py). Such a start is
// detected and the labels are meshed again with every component seeded.
TEST(PhantomDataset, AnOrganMeshThatCgalStartedBadlyIsMeshedAgain)
{
    const PhantomSpec spec = PhantomSpec::preset_spec("small");
    const LabelVolume labels = make_cirs057a_phantom(spec.voxel_mm);
    LabelRoles roles = phantom_label_roles();
    roles.body.clear(), roles.bone.clear(); // the organs alone (phantom --organs-only)
    std::set<std::int32_t> present;
    for (const auto l : labels.labels) present.insert(l);
    nlohmann::json ranges;
    const TissueTable tissues = draw_ground_truth_tissues(MaterialSet::healthy, roles, present, 9, ranges);
    const GroundTruthModel m = build_body_model(labels, roles, tissues, spec.ground_truth_mesh, 9, parse_organ_support("posterior", "--organ-support"));
    ASSERT_EQ(m.name, "organs");
    // The organs' volume: the liver alone is about 1.1e6 mm³ at this preset; 505 tetrahedra were not.
    double volume = 0.0;
    for (std::size_t c = 0; c < m.mesh.cell_count(); ++c) {
        const auto cell = m.mesh.cell(c);
        const Vec3& x0 = m.mesh.nodes[cell[0]];
        volume += std::abs((m.mesh.nodes[cell[1]] - x0).dot((m.mesh.nodes[cell[2]] - x0).cross(m.mesh.nodes[cell[3]] - x0))) / 6.0;
    }
    double voxels = 0.0;
    for (const auto l : labels.labels)
        if (tissues.find(l)) voxels += 1.0;
    voxels *= labels.geometry.spacing.prod();
    EXPECT_GT(m.mesh.cell_count(), 5000u);
    EXPECT_GT(volume, 0.8 * voxels) << volume << " mm³ meshed of " << voxels;
}

} // namespace physreg
