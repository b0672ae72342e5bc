// Real third-party data in ../shared/data (skipped when absent): the product never needs it.
#include "physreg/io/gmsh.hpp"
#include "physreg/io/image_io.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/label_grid.hpp"
#include "physreg/mesh/quality.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

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
