// SPDX-License-Identifier: GPL-3.0-or-later
// Real third-party data in ../shared/data (skipped when absent): the product never needs it.
#include "physreg/io/gmsh.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "physreg/io/landmarks_io.hpp"
#include "physreg/phantom/dataset.hpp"
#include "physreg/evaluation/tre.hpp"
#include "physreg/registration/compression/estimation.hpp"
#include "physreg/registration/compression/liver_model.hpp"
#include "test_support.hpp"

#include <cstdio>

namespace physreg {

class DataMsdMasks : public ::testing::TestWithParam<std::string> {};

TEST_P(DataMsdMasks, LiverAndVesselMasksMeshAtFullResolution)
{
    PHYSREG_REQUIRE_SHARED_DATA("msd-hepaticvessel-liver-vessel-masks");
    const std::string case_id = GetParam();
    const LabelVolume liver = read_label_volume(shared_data / ("hepaticvessel_" + case_id + "_liver.nii.gz"));
    TissueTable parenchyma;
    parenchyma.tissues = {{1, "parenchyma", 2e5, 0.49, 1000}};
    const auto result = mesh_label_volume(liver, parenchyma, {}, "liver " + case_id);
    const auto voxels = count_labels(liver).at(1);
    // One hexahedron per voxel (before any piece is dropped): the volume is the voxel volume.
    EXPECT_EQ(static_cast<std::int64_t>(result.mesh.cell_count()), voxels);
    EXPECT_NEAR(measure_quality(result.mesh).volume_mm3, voxels * liver.geometry.voxel_volume_mm3(), 1e-6 * voxels);
    EXPECT_EQ(measure_quality(result.mesh).inverted_cells, 0u);
    // Grid meshing as paper 000 does.
    MeshingOptions grid;
    grid.grid_dims = Index3{74, 54, 18};
    grid.components = ComponentPolicy::keep_largest;
    const auto coarse = mesh_label_volume(liver, parenchyma, grid, "liver " + case_id);
    EXPECT_GT(coarse.mesh.cell_count(), 1000u);
    EXPECT_EQ(coarse.mesh.cell_count(), split_hexahedra_into_tetrahedra(coarse.mesh).cell_count() / 6);
    // The two-label vessel masks (labels 1, 2) mesh as two tissues.
    const LabelVolume vessels = read_label_volume(shared_data / ("hepaticvessel_" + case_id + "_vsnet.nii.gz"));
    TissueTable vessel_table;
    vessel_table.tissues = {{1, "hepatic_vein", 1e6, 0.49, 1000}, {2, "portal_vein", 1e6, 0.49, 1000}};
    const auto v = mesh_label_volume(vessels, vessel_table, {}, "vessels " + case_id);
    EXPECT_EQ(volume_per_label(v.mesh).size(), 2u);
}

INSTANTIATE_TEST_SUITE_P(Cases, DataMsdMasks, ::testing::Values("002", "008", "010"));

TEST(DataCirs057a, SegmentedPhantomCtMeshesOnPaperGrid)
{
    PHYSREG_REQUIRE_SHARED_DATA("cirs057a-ct");
    const LabelVolume labels = read_label_volume(shared_data / "labels.nii.gz");
    TissueTable table;
    std::int32_t next = 1;
    for (const auto& [label, count] : count_labels(labels))
        if (label != 0) table.tissues.push_back({label, "tissue_" + std::to_string(next++), 1e5, 0.45, 1000});
    MeshingOptions options;
    options.grid_dims = Index3{74, 54, 18};
    const auto result = mesh_label_volume(labels, table, options, "cirs057a");
    EXPECT_GT(result.mesh.cell_count(), 10000u);
    EXPECT_EQ(measure_quality(result.mesh).inverted_cells, 0u);
}

TEST(DataSofaLiver, GmshVersionOneMeshesRead)
{
    PHYSREG_REQUIRE_SHARED_DATA("sofa-liver");
    const VolumeMesh coarse = read_gmsh(shared_data / "liver.msh");
    EXPECT_EQ(coarse.node_count(), 181u);
    EXPECT_EQ(coarse.cell_count(), 596u);
    EXPECT_EQ(coarse.cell_type, CellType::tetrahedron);
    const VolumeMesh second = read_gmsh(shared_data / "liver2.msh");
    EXPECT_EQ(second.node_count(), 507u);
    EXPECT_EQ(second.cell_count(), 1493u);
    for (const VolumeMesh* m : {&coarse, &second}) {
        const auto q = measure_quality(*m);
        EXPECT_GT(q.volume_mm3, 0.0);
    }
    const SurfaceMesh surface = read_surface(shared_data / "liver-smooth.obj");
    EXPECT_GT(surface.triangles.size(), 100u);
}

TEST(DataSofaLiver, FineVtuReads)
{
    PHYSREG_REQUIRE_SHARED_DATA("sofa-mor-liverFine");
    const VolumeMesh fine = read_volume_mesh(shared_data / "liverFine.vtu");
    EXPECT_EQ(fine.node_count(), 4293u);
    EXPECT_EQ(fine.cell_count(), 22019u);
}

TEST(DataDigitalTwin, PatientLiverSurfaceReads)
{
    PHYSREG_REQUIRE_SHARED_DATA("digitaltwin-liver-portal-centerlines");
    const SurfaceMesh liver = read_surface(shared_data / "patient3_liver.stl");
    EXPECT_GT(liver.triangles.size(), 1000u);
}

} // namespace physreg

// physreg phantom --from-labels on the real label maps (issue 4): the real phantom's CT labels and
// a patient's liver + vessel masks, with a coarse ground truth so the test stays short.
namespace physreg {

void check_from_labels_dataset(const std::filesystem::path& root)
{
    const PhantomDataset d = read_phantom_dataset(root);
    ASSERT_EQ(d.states.size(), 4u); // rest, A, B, insufflation
    const LabelVolume rest = read_label_volume(d.path(d.state("rest").files.at("labels")));
    for (const auto& s : d.states) {
        SCOPED_TRACE(s.name);
        const auto landmarks = read_landmarks(d.path(s.files.at("landmarks")));
        ASSERT_EQ(landmarks.size(), 25u);
        EXPECT_EQ(std::count_if(landmarks.begin(), landmarks.end(), [](const Landmark& l) { return l.type == LandmarkType::surface; }), 11);
        const LabelVolume labels = read_label_volume(d.path(s.files.at("labels")));
        EXPECT_EQ(labels.geometry.size, rest.geometry.size);
        if (s.kind == "rest") continue;
        // The tool moves the tissue by about its depth; 3 % of the parenchyma's E on the organs'
        // anterior faces moves the real CT's liver 0.3 mm (its posterior faces held).
        EXPECT_GT(s.max_displacement_mm, s.kind == "insufflation" ? 0.1 : 0.5);
        EXPECT_EQ(read_displacement_field(d.path(s.files.at("displacement"))).geometry.size, rest.geometry.size);
    }
}

TEST(DataPhantomFromLabels, RealPhantomCtLabelsThroughTheBody)
{
    PHYSREG_REQUIRE_SHARED_DATA("cirs057a-ct");
    PhantomSpec spec = PhantomSpec::preset_spec("small");
    spec.preset = "from-labels";
    spec.labels_file = shared_data / "labels.nii.gz"; // 0 air, 1 body, 2 liver, 3 lesions, 4 vessels, 5 bone, 6 kidneys
    // The body ground truth (gel, organs, bone held, base on the table), the tool on the skin. The
    // real CT's ribs come within 1 mm of the skin beside the liver: the compression sites keep the
    // tool's patch off bone (whose held surface nodes the tool could not push away).
    ASSERT_TRUE(spec.simulate_body);
    spec.depths_mm = {6, 8};
    spec.tool.radius_mm = 12.0;
    spec.calculix_validation = false;
    test::TempDir dir;
    generate_phantom_dataset(spec, dir / "ds", false, {});
    check_from_labels_dataset(dir / "ds");
    // Paper 000's body model (hexahedra, Neo-Hookean, literature moduli, its default grid) driven by
    // the tool alone moves the landmarks toward the truth.
    const PhantomDataset d = read_phantom_dataset(dir / "ds");
    const LabelVolume rest_labels = read_label_volume(d.path(d.state("rest").files.at("labels")));
    const LandmarkSet rest = read_landmarks(d.path(d.state("rest").files.at("landmarks")));
    ModelParameters parameters;
    parameters.region = ModelRegion::body;
    parameters.grid = default_model_grid(rest_labels, d.roles, ModelRegion::body);
    const LiverModel body = build_liver_model(rest_labels, d.roles, parameters, "CIRS CT rest labels");
    EXPECT_FALSE(body.fixed_nodes.empty()); // the ribs and spine held
    std::vector<TreReport> model, at_rest;
    for (const auto& c : compression_cases(d, {"A", "B"})) {
        const auto prediction = predict_compression(body, c.tool, rest, {}, c.name);
        model.push_back(compute_tre(prediction.landmarks, c.truth, c.name));
        at_rest.push_back(compute_tre(rest, c.truth, c.name + " at rest"));
    }
    const TreReport m = pool_tre(model), r = pool_tre(at_rest);
    std::printf("body model on the CIRS CT labels, A and B: TRE %.3f mm (internal %.3f), landmarks at rest %.3f mm (internal %.3f)\n",
                m.all.mean_mm, m.internal.mean_mm, r.all.mean_mm, r.internal.mean_mm);
    EXPECT_GT(r.all.mean_mm, 0.05); // the landmarks did move
    EXPECT_LT(m.all.mean_mm, 0.85 * r.all.mean_mm) << m.all.mean_mm << " mm vs " << r.all.mean_mm << " mm at rest";
}

TEST(DataPhantomFromLabels, PatientLiverAndVesselMasks)
{
    PHYSREG_REQUIRE_SHARED_DATA("msd-hepaticvessel-liver-vessel-masks");
    PhantomSpec spec = PhantomSpec::preset_spec("small");
    spec.preset = "from-labels";
    spec.labels_file = shared_data / "hepaticvessel_008_liver.nii.gz";
    spec.vessel_mask = shared_data / "hepaticvessel_008_vsnet.nii.gz";
    spec.roles = parse_label_roles("liver=1", "test");
    spec.depths_mm = {6, 8}; // no body label: the organs alone, pressed directly
    test::TempDir dir;
    generate_phantom_dataset(spec, dir / "ds", false, {});
    check_from_labels_dataset(dir / "ds");
    const PhantomDataset d = read_phantom_dataset(dir / "ds");
    EXPECT_EQ(d.roles.vessel.size(), 1u); // the mask became a vessel label
}

} // namespace physreg
