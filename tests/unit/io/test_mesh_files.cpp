// SPDX-License-Identifier: GPL-3.0-or-later
#include "physreg/core/error.hpp"
#include "physreg/io/gmsh.hpp"
#include "physreg/io/mesh_io.hpp"
#include "physreg/io/surface_io.hpp"
#include "physreg/io/point_cloud.hpp"
#include "physreg/mesh/hex_meshing.hpp"
#include "physreg/mesh/surface_extraction.hpp"
#include "physreg/mesh/tet_split.hpp"
#include "test_support.hpp"

#include <fstream>
#include <zlib.h>

namespace physreg {
namespace {

VolumeMesh sample_hex_mesh()
{
    const auto volume = test::make_volume({5, 4, 3}, [](int i, int j, int k) { return std::uint16_t(i < 1 ? 0 : (j + k) % 2 + 1); },
                                          Vec3(1.5, 0.75, 2.0), Vec3(3, -4, 5), test::oblique_rotation());
    TissueTable t = default_tissue_table();
    return mesh_label_volume(volume, t, {}, "sample").mesh;
}

void expect_same_mesh(const VolumeMesh& a, const VolumeMesh& b)
{
    EXPECT_EQ(a.cell_type, b.cell_type);
    ASSERT_EQ(a.node_count(), b.node_count());
    for (std::size_t n = 0; n < a.node_count(); ++n) EXPECT_EQ(a.nodes[n], b.nodes[n]) << "node " << n;
    EXPECT_EQ(a.cells, b.cells);
    EXPECT_EQ(a.cell_labels, b.cell_labels);
}

std::string read_all(const std::filesystem::path& p)
{
    std::ifstream in(p, std::ios::binary);
    return {(std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()};
}

std::string error_of(const std::function<void()>& f) { return test::error_message(f); }

} // namespace

TEST(IoMeshFiles, VtuRoundTripKeepsMeshGridAndData)
{
    test::TempDir dir;
    const VolumeMesh mesh = sample_hex_mesh();
    MeshData data;
    DataArray u{"displacement", 3, {}};
    for (std::size_t n = 0; n < mesh.node_count(); ++n) u.values.insert(u.values.end(), {0.1 * n, -0.2 * n, 1.0 / (n + 1)});
    data.point_data.push_back(u);
    DataArray stress{"stress_pa", 1, std::vector<double>(mesh.cell_count(), 3.5)};
    data.cell_data.push_back(stress);
    write_vtu(dir / "m.vtu", mesh, data);
    MeshData back_data;
    const VolumeMesh back = read_vtu(dir / "m.vtu", &back_data);
    expect_same_mesh(mesh, back);
    ASSERT_TRUE(back.grid.has_value());
    EXPECT_EQ(back.grid->dims, mesh.grid->dims);
    EXPECT_EQ(back.grid->origin, mesh.grid->origin);
    EXPECT_EQ(back.cell_grid_index, mesh.cell_grid_index);
    ASSERT_NE(back_data.find_point("displacement"), nullptr);
    EXPECT_EQ(back_data.find_point("displacement")->values, u.values);
    EXPECT_EQ(back_data.find_cell("stress_pa")->values, stress.values);

    const VolumeMesh tets = split_hexahedra_into_tetrahedra(mesh);
    write_vtu(dir / "t.vtu", tets);
    expect_same_mesh(tets, read_vtu(dir / "t.vtu"));
}

TEST(IoMeshFiles, VtuReadsAsciiAndZlibCompressedFiles)
{
    test::TempDir dir;
    // Hand-written ascii file, as older tools write them (SOFA's liverFine.vtu is one).
    std::ofstream(dir / "a.vtu") << R"(<VTKFile type="UnstructuredGrid" version="0.1" byte_order="BigEndian">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="2">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<CellData><DataArray type="Int32" Name="MaterialIds" format="ascii">7 7</DataArray></CellData>
<Cells><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 3 0 1 2</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">4 7</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10 5</DataArray></Cells>
</Piece></UnstructuredGrid></VTKFile>)";
    const VolumeMesh a = read_vtu(dir / "a.vtu");
    EXPECT_EQ(a.cell_count(), 1u); // the triangle is skipped
    EXPECT_EQ(a.cell_labels[0], 7);
    EXPECT_EQ(a.nodes[3], Vec3(0, 0, 1));

    // zlib-compressed inline binary (what VTK writes by default).
    auto compressed_block = [](const std::vector<double>& values) {
        const std::string raw(reinterpret_cast<const char*>(values.data()), values.size() * 8);
        uLongf size = compressBound(static_cast<uLong>(raw.size()));
        std::string packed(size, '\0');
        compress(reinterpret_cast<Bytef*>(packed.data()), &size, reinterpret_cast<const Bytef*>(raw.data()), static_cast<uLong>(raw.size()));
        packed.resize(size);
        const std::uint32_t header[4] = {1, static_cast<std::uint32_t>(raw.size()), static_cast<std::uint32_t>(raw.size()),
                                         static_cast<std::uint32_t>(size)};
        static constexpr char table[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        auto b64 = [&](const std::string& in) {
            std::string out;
            for (std::size_t i = 0; i < in.size(); i += 3) {
                unsigned v = (unsigned char)in[i] << 16;
                if (i + 1 < in.size()) v |= (unsigned char)in[i + 1] << 8;
                if (i + 2 < in.size()) v |= (unsigned char)in[i + 2];
                out += table[v >> 18];
                out += table[(v >> 12) & 63];
                out += i + 1 < in.size() ? table[(v >> 6) & 63] : '=';
                out += i + 2 < in.size() ? table[v & 63] : '=';
            }
            return out;
        };
        return b64(std::string(reinterpret_cast<const char*>(header), 16)) + b64(packed);
    };
    std::ofstream(dir / "z.vtu") << R"(<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" compressor="vtkZLibDataCompressor">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="1">
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">)"
                                 << compressed_block({0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 2}) << R"(</DataArray></Points>
<Cells><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray></Cells>
</Piece></UnstructuredGrid></VTKFile>)";
    const VolumeMesh z = read_vtu(dir / "z.vtu");
    EXPECT_EQ(z.nodes[1], Vec3(2, 0, 0));
    EXPECT_EQ(z.nodes[3], Vec3(0, 0, 2));
}

TEST(IoMeshFiles, GmshRoundTripsInBothVersions)
{
    test::TempDir dir;
    const VolumeMesh hex = sample_hex_mesh();
    const VolumeMesh tets = split_hexahedra_into_tetrahedra(hex);
    for (auto version : {GmshVersion::v2_2, GmshVersion::v4_1}) {
        write_gmsh(dir / "h.msh", hex, version);
        expect_same_mesh(hex, read_gmsh(dir / "h.msh"));
        write_gmsh(dir / "t.msh", tets, version);
        expect_same_mesh(tets, read_gmsh(dir / "t.msh"));
    }
}

TEST(IoMeshFiles, GmshVersionOneAndBinaryVersionTwo)
{
    test::TempDir dir;
    std::ofstream(dir / "v1.msh") << "$NOD\n4\n10 0 0 0\n11 1 0 0\n12 0 1 0\n13 0 0 1\n$ENDNOD\n$ELM\n2\n"
                                     "1 2 5 5 3 10 11 12\n2 4 9 1 4 10 11 12 13\n$ENDELM\n";
    const VolumeMesh v1 = read_gmsh(dir / "v1.msh");
    ASSERT_EQ(v1.cell_count(), 1u);
    EXPECT_EQ(v1.cell_labels[0], 9);
    EXPECT_EQ(v1.cells, (std::vector<std::int32_t>{0, 1, 2, 3}));

    std::ofstream bin(dir / "b.msh", std::ios::binary);
    bin << "$MeshFormat\n2.2 1 8\n";
    const int one = 1;
    bin.write(reinterpret_cast<const char*>(&one), 4);
    bin << "\n$EndMeshFormat\n$Nodes\n4\n";
    const double xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int n = 0; n < 4; ++n) {
        const int id = n + 1;
        bin.write(reinterpret_cast<const char*>(&id), 4);
        bin.write(reinterpret_cast<const char*>(xyz[n]), 24);
    }
    bin << "\n$EndNodes\n$Elements\n1\n";
    const int element[] = {4, 1, 2, /*id*/ 1, /*tags*/ 3, 3, /*nodes*/ 1, 2, 3, 4};
    bin.write(reinterpret_cast<const char*>(element), sizeof(element));
    bin << "\n$EndElements\n";
    bin.close();
    const VolumeMesh b = read_gmsh(dir / "b.msh");
    ASSERT_EQ(b.cell_count(), 1u);
    EXPECT_EQ(b.cell_labels[0], 3);
    EXPECT_EQ(b.nodes[3], Vec3(0, 0, 1));
}

TEST(IoMeshFiles, TruncatedAndCorruptMeshesAreRefused)
{
    test::TempDir dir;
    const VolumeMesh mesh = sample_hex_mesh();
    write_vtu(dir / "m.vtu", mesh);
    const std::string vtu = read_all(dir / "m.vtu");
    std::ofstream(dir / "cut.vtu", std::ios::binary) << vtu.substr(0, vtu.size() * 2 / 3);
    EXPECT_NE(error_of([&] { read_vtu(dir / "cut.vtu"); }).find("cut.vtu"), std::string::npos);
    std::string flipped = vtu;
    flipped[vtu.find("format=\"binary\">") + 40] = '#'; // not base64
    std::ofstream(dir / "bad.vtu", std::ios::binary) << flipped;
    EXPECT_NE(error_of([&] { read_vtu(dir / "bad.vtu"); }).find("bad.vtu"), std::string::npos);

    write_gmsh(dir / "m.msh", mesh);
    const std::string msh = read_all(dir / "m.msh");
    std::ofstream(dir / "cut.msh") << msh.substr(0, msh.size() / 2);
    EXPECT_NE(error_of([&] { read_gmsh(dir / "cut.msh"); }).find("cut.msh"), std::string::npos);
    std::ofstream(dir / "dangling.msh") << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n"
                                           "$Elements\n1\n1 4 2 1 1 1 2 3 4\n$EndElements\n";
    EXPECT_NE(error_of([&] { read_gmsh(dir / "dangling.msh"); }).find("not defined"), std::string::npos);
    std::ofstream(dir / "empty.vtu") << "";
    EXPECT_FALSE(error_of([&] { read_volume_mesh(dir / "empty.vtu"); }).empty());
    EXPECT_NE(error_of([&] { read_volume_mesh(dir / "none.vtu"); }).find("does not exist"), std::string::npos);
}

TEST(IoMeshFiles, SurfaceRoundTrips)
{
    test::TempDir dir;
    const SurfaceMesh s = extract_surfaces(sample_hex_mesh());
    for (const char* name : {"s.ply", "s.obj"}) {
        SCOPED_TRACE(name);
        write_surface(dir / name, s);
        const SurfaceMesh back = read_surface(dir / name);
        EXPECT_EQ(back.vertices, s.vertices);
        EXPECT_EQ(back.triangles, s.triangles);
        EXPECT_EQ(back.labels, s.labels);
    }
    // STL is unindexed single precision: vertices are welded back, coordinates within float rounding.
    write_surface(dir / "s.stl", s);
    const SurfaceMesh stl = read_surface(dir / "s.stl");
    EXPECT_EQ(stl.vertices.size(), s.vertices.size());
    ASSERT_EQ(stl.triangles.size(), s.triangles.size());
    for (std::size_t t = 0; t < s.triangles.size(); ++t)
        for (int v = 0; v < 3; ++v)
            EXPECT_LT((stl.vertices[stl.triangles[t][v]] - s.vertices[s.triangles[t][v]]).norm(), 1e-5);
    std::ofstream(dir / "cut.stl", std::ios::binary) << read_all(dir / "s.stl").substr(0, 200);
    EXPECT_FALSE(error_of([&] { read_surface(dir / "cut.stl"); }).empty());
}

TEST(IoMeshFiles, LegacyVtkPolydataKeepsLabelsNormalsAndServesAsAPointCloud)
{
    test::TempDir dir;
    SurfaceMesh s = extract_surfaces(sample_hex_mesh());
    for (std::size_t v = 0; v < s.vertices.size(); ++v) {
        s.vertex_labels.push_back(static_cast<std::int32_t>(v % 3));
        s.vertex_normals.push_back(Vec3(0, 0, 1));
    }
    write_surface(dir / "s.vtk", s);
    const SurfaceMesh back = read_surface(dir / "s.vtk");
    ASSERT_EQ(back.vertices.size(), s.vertices.size());
    for (std::size_t v = 0; v < s.vertices.size(); ++v) EXPECT_LT((back.vertices[v] - s.vertices[v]).norm(), 1e-8);
    EXPECT_EQ(back.triangles, s.triangles);
    EXPECT_EQ(back.labels, s.labels);
    EXPECT_EQ(back.vertex_labels, s.vertex_labels);
    EXPECT_EQ(back.vertex_normals, s.vertex_normals);
    const LabelledPointCloud cloud = read_point_cloud(dir / "s.vtk");
    EXPECT_EQ(cloud.points.size(), s.vertices.size());
    EXPECT_EQ(cloud.labels, s.vertex_labels);
    // A quad fan and a vertices-only cloud written by hand (as ParaView's "Save Data", ASCII).
    std::ofstream(dir / "quad.vtk") << "# vtk DataFile Version 3.0\nq\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\n"
                                       "POLYGONS 1 5\n4 0 1 2 3\nCELL_DATA 1\nSCALARS region int\nLOOKUP_TABLE default\n2\n";
    const SurfaceMesh quad = read_surface(dir / "quad.vtk");
    ASSERT_EQ(quad.triangles.size(), 2u);
    EXPECT_EQ(quad.labels[1][0], 2);
    std::ofstream(dir / "binary.vtk") << "# vtk DataFile Version 3.0\nb\nBINARY\nDATASET POLYDATA\n";
    EXPECT_NE(error_of([&] { read_surface(dir / "binary.vtk"); }).find("binary legacy VTK"), std::string::npos);
    std::ofstream(dir / "grid.vtk") << "# vtk DataFile Version 3.0\ng\nASCII\nDATASET UNSTRUCTURED_GRID\n";
    EXPECT_NE(error_of([&] { read_surface(dir / "grid.vtk"); }).find("only DATASET POLYDATA"), std::string::npos);
    std::ofstream(dir / "cut.vtk") << "# vtk DataFile Version 3.0\nc\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1\n";
    EXPECT_NE(error_of([&] { read_surface(dir / "cut.vtk"); }).find("truncated"), std::string::npos);
}

} // namespace physreg
