// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// VTK XML unstructured grid (.vtu), the format ParaView, VTK and meshio open. Written as inline
// base64 "binary" arrays with UInt64 headers; read from ascii, binary (raw or zlib-compressed),
// and appended (raw or base64) files, either byte order.
#include "physreg/mesh/volume_mesh.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace physreg {

struct DataArray {
    std::string name;
    int components = 1;
    std::vector<double> values; ///< tuple-major: values[i * components + c]
};

struct MeshData {
    std::vector<DataArray> point_data; ///< e.g. "displacement" (mm), 3 components
    std::vector<DataArray> cell_data;
    const DataArray* find_point(const std::string& name) const;
    const DataArray* find_cell(const std::string& name) const;
};

/// Writes nodes, cells, the per-cell "tissue" label, the grid (as field data "physreg_grid" and
/// cell data "grid_index") when the mesh has one, and `data`. Atomic: temporary file + rename.
void write_vtu(const std::filesystem::path& path, const VolumeMesh& mesh, const MeshData& data = {});

/// Reads tetrahedra or hexahedra (other 3-D cells are an Error; 0-2-D cells are skipped). Cell
/// labels come from "tissue", else "gmsh:physical", "CellEntityIds" or "MaterialIds", else 1.
VolumeMesh read_vtu(const std::filesystem::path& path, MeshData* data = nullptr);

} // namespace physreg
