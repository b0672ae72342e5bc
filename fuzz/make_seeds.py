# SPDX-License-Identifier: GPL-3.0-or-later
"""Writes the seed corpora under fuzz/corpus/ from physreg's own writers (small files: the fuzzer
mutates them faster) plus hand-written variants of the formats our writers do not produce.

    PYTHONPATH=build/python python3 fuzz/make_seeds.py
Each seed starts with the selector byte its target reads first (see fuzz_*.cpp)."""
import os
import pathlib
import tempfile

import numpy as np
import physreg

HERE = pathlib.Path(__file__).resolve().parent
CORPUS = HERE / "corpus"


def put(target, name, data, selector=None):
    folder = CORPUS / target
    folder.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    if selector is not None:
        data = bytes([selector]) + data
    (folder / name).write_bytes(data)


def main():
    tmp = pathlib.Path(tempfile.mkdtemp())
    labels = np.zeros((2, 2, 3), dtype=np.uint16)  # [z, y, x]
    labels[:, :, :2] = 1
    labels[1, 1, 2] = 3
    geometry = physreg.ImageGeometry(spacing=(1.0, 1.5, 2.0), origin=(-3.0, 4.0, 0.5))
    hexes = physreg.mesh_from_labels(labels, geometry, kind="hex")

    # Volume meshes: selector even = .vtu, odd = .msh.
    physreg.write_mesh(tmp / "m.vtu", hexes)
    put("volume_mesh", "hex.vtu", (tmp / "m.vtu").read_bytes(), 0)
    physreg.write_mesh(tmp / "m.msh", hexes)
    put("volume_mesh", "hex41.msh", (tmp / "m.msh").read_bytes(), 1)
    physreg.write_mesh(tmp / "m.v2.msh", hexes)
    put("volume_mesh", "hex22.msh", (tmp / "m.v2.msh").read_bytes(), 1)
    put("volume_mesh", "tet_ascii.vtu", """<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="1">
<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></Points>
<Cells><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray></Cells>
<CellData><DataArray type="Int32" Name="tissue" format="ascii">2</DataArray></CellData>
<PointData><DataArray type="Float32" Name="displacement" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 0 1 0 0 0 1</DataArray></PointData>
</Piece></UnstructuredGrid></VTKFile>
""", 0)
    put("volume_mesh", "tet_appended_raw.vtu", b"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" header_type="UInt32">
<UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="1">
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="0"/></Points>
<Cells><DataArray type="Int32" Name="connectivity" format="appended" offset="52"/>
<DataArray type="Int32" Name="offsets" format="appended" offset="72"/>
<DataArray type="UInt8" Name="types" format="appended" offset="80"/></Cells>
</Piece></UnstructuredGrid>
<AppendedData encoding="raw">_""" + np.array([48], "<u4").tobytes() + np.array(
        [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1], "<f4").tobytes() + np.array([16], "<u4").tobytes() + np.array(
        [0, 1, 2, 3], "<i4").tobytes() + np.array([4], "<u4").tobytes() + np.array([4], "<i4").tobytes() + np.array(
        [1], "<u4").tobytes() + bytes([10]) + b"\n</AppendedData></VTKFile>\n", 0)
    put("volume_mesh", "tet22_ascii.msh", """$MeshFormat
2.2 0 8
$EndMeshFormat
$Nodes
4
1 0 0 0
2 1 0 0
3 0 1 0
4 0 0 1
$EndNodes
$Elements
2
1 2 2 7 1 1 2 3
2 4 2 7 1 1 2 3 4
$EndElements
""", 1)

    # Surfaces: selector &3 = stl, ply, obj, vtk; selector 5 / 7 reads .ply / .vtk as a point set.
    surface = physreg.boundary_surface(hexes)
    for selector, ext in ((0, "stl"), (1, "ply"), (2, "obj"), (3, "vtk")):
        physreg.write_surface(tmp / f"s.{ext}", surface)
        put("surface", f"boundary.{ext}", (tmp / f"s.{ext}").read_bytes(), selector)
    put("surface", "points.ply", (tmp / "s.ply").read_bytes(), 5)
    put("surface", "ascii.stl", """solid t
facet normal 0 0 1
 outer loop
  vertex 0 0 0
  vertex 1 0 0
  vertex 0 1 0
 endloop
endfacet
endsolid t
""", 0)
    put("surface", "ascii.ply", """ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
property float nx
property float ny
property float nz
property int label
element face 1
property list uchar int vertex_indices
end_header
0 0 0 0 0 1 1
1 0 0 0 0 1 1
0 1 0 0 0 1 2
3 0 1 2
""", 5)
    put("surface", "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng label_1_0\nf 1 2 3 4\nf 1/1/1 3//3 -1\n", 2)

    # Landmarks: selector &3 = csv, fcsv, mrk.json.
    positions = np.array([[1.0, 2.0, 3.0], [-4.5, 0.25, 7.0]])
    for selector, ext in ((0, "csv"), (1, "fcsv"), (2, "mrk.json")):
        physreg.write_landmarks(tmp / f"l.{ext}", ["tumour_centre", "vessel_bifurcation"], positions)
        put("landmarks", f"two.{ext.replace('.', '_')}", (tmp / f"l.{ext}").read_bytes(), selector)
    put("landmarks", "ras.fcsv", "# Markups fiducial file version = 4.11\n# CoordinateSystem = RAS\n"
        "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n"
        "vtkMRMLMarkupsFiducialNode_0,1,2,3,0,0,0,1,1,1,0,F-1,,\n", 1)

    # Configurations: selector %3 = tissue table YAML, tissue table JSON, simulation case YAML.
    put("config", "tissues.yaml", """tissues:
  - {label: 1, name: parenchyma, young_modulus_pa: 2.0e5, poisson_ratio: 0.49, density_kg_m3: 1000}
  - {label: 3, name: tumour, young_modulus_pa: 5.0e6, poisson_ratio: 0.45, mooney_rivlin_c01_fraction: 0.2}
ignore_labels: [7]
""", 0)
    put("config", "tissues.json", '{"tissues": [{"label": 2, "name": "vessel", "young_modulus_pa": 1e6, '
        '"poisson_ratio": 0.49}]}\n', 1)
    import re
    documented = re.findall(r"```yaml\n(.*?)```", (HERE.parent / "docs" / "simulate.md").read_text(), re.S)
    put("config", "case_documented.yaml", documented[0], 2)
    put("config", "case_newton_labels.yaml", """labels: labels.nii.gz
grid: 8x6x4
element: tetrahedron
material_law: corotational
solver: {method: newton, linear: cholmod, tolerance: 1.0e-7, load_steps: 2}
constraints:
  - {name: base, select: {nodes: [0, 1, 2]}, fixed: [x, z]}
output: {directory: out, frames: 2}
""", 2)
    put("config", "case_backward_euler.yaml", """mesh: block.msh
material_law: mooney-rivlin
solver: {method: backward-euler, time_step_s: 0.01, duration_s: 0.1, rayleigh_mass_per_s: 2, mass: consistent, tangent: every-step, newton_iterations: 1}
indenters:
  - {name: plate, shape: plane, normal: [0, 1, 0], path_mm: [[0, 0, 0], [0, 2, 0]]}
  - {name: box, shape: box, half_extents_mm: [1, 2, 3], path_mm: [[0, 0, 0], [0, 1, 0]]}
output: {directory: out}
""", 2)

    # Images: selector &3 = nii, nrrd, mha; bits 2-3 = label / scalar / displacement reader.
    for selector, ext in ((0, "nii"), (1, "nrrd"), (2, "mha")):
        physreg.write_labels(tmp / f"i.{ext}", labels, geometry)
        put("image", f"labels.{ext}", (tmp / f"i.{ext}").read_bytes(), selector)
    physreg.write_image(tmp / "f.nrrd", labels.astype(np.float32) * 0.5, geometry)
    put("image", "scalar.nrrd", (tmp / "f.nrrd").read_bytes(), 1 | 4)
    physreg.write_displacement_field(tmp / "d.mha", np.ones((2, 2, 3, 3), np.float32), geometry)
    put("image", "field.mha", (tmp / "d.mha").read_bytes(), 2 | 8)

    # Label volumes for meshing: sizes, spacing/direction, options, options, then labels.
    rng = np.random.default_rng(19)
    put("label_mesh", "cube.bin", bytes([2, 2, 2, 0, 0, 0]) + bytes([1] * 27))
    put("label_mesh", "two_blobs.bin", bytes([4, 1, 1, 0, 0, 1]) + bytes([1, 0, 0, 1, 1]))
    put("label_mesh", "grid.bin", bytes([5, 4, 3, 0x40, 0b0101011, 5]) + bytes(rng.integers(0, 4, 120, dtype=np.uint8)))
    put("label_mesh", "diagonal.bin", bytes([1, 1, 1, 0x80, 0, 4]) + bytes([1, 0, 0, 1, 0, 0, 0, 1]))

    # The enrichment database: a tiny one (fine grid 6x5x3, coarse 3x3x3, one condition) from
    # `physreg phantom --preset small --seed 3 --depths 8,10,8,6 -o ph` then
    # `physreg enrich build --dataset ph --grid 6x5x3 --coarse-grid 3x3x3 --positions B --depths 6 -o tiny.phe`,
    # passed in PHYSREG_SEED_DATABASE.
    database = os.environ.get("PHYSREG_SEED_DATABASE")
    if database:
        put("enrichment_database", "tiny.phe", pathlib.Path(database).read_bytes())

    igtl_seeds()


def igtl_seeds():
    """OpenIGTLink messages as a tracker, Slicer or a cloud source sends them (selector 1: the target
    writes the CRC in; 0: as given, with a correct CRC here too)."""
    import struct
    table = []
    for i in range(256):
        c = i << 56
        for _ in range(8):
            c = ((c << 1) ^ 0x42F0E1EBA9EA3693) if c & (1 << 63) else (c << 1)
            c &= 0xFFFFFFFFFFFFFFFF
        table.append(c)

    def crc64(data):
        c = 0
        for b in data:
            c = table[((c >> 56) ^ b) & 0xFF] ^ ((c << 8) & 0xFFFFFFFFFFFFFFFF)
        return c

    def message(kind, device, body, version=1):
        return struct.pack(">H12s20sQQQ", version, kind.encode(), device.encode(), 1 << 32, len(body), crc64(body)) + body

    transform = struct.pack(">12f", 1, 0, 0, 0, 1, 0, 0, 0, 1, -10.5, 20.0, 35.25)
    put("igtl_message", "transform_v1.bin", message("TRANSFORM", "tool", transform), 0)
    extended = struct.pack(">HHIQ", 12, 2, 0, 0)  # extended header: size, metadata header size, metadata size, message id
    put("igtl_message", "transform_v2.bin", message("TRANSFORM", "tool", extended + transform + struct.pack(">H", 0), version=2), 1)
    put("igtl_message", "status_v2.bin", message("STATUS", "Slicer", extended + struct.pack(">HQ20s", 1, 0, b"") + b"\0" + struct.pack(">H", 0), 2), 1)
    xml = b'<Command Name="status" />'
    put("igtl_message", "command.bin", message("STRING", "CMD_1", struct.pack(">HH", 3, len(xml)) + xml), 0)
    points = [(0.0, 1.0, 2.0), (10.5, -3.0, 7.25), (-4.0, 8.0, 1.0)]
    polydata = struct.pack(">10I", len(points), 0, 0, 0, 0, 0, 0, 0, 0, 0) + b"".join(struct.pack(">3f", *p) for p in points)
    put("igtl_message", "cloud.bin", message("POLYDATA", "cloud", polydata), 1)
    # A 3 × 2 × 2 uint8 segmentation, RAS, 1.5 mm voxels, centred at (10, -5, 20).
    image = struct.pack(">HBBBB3H12f3H3H", 1, 1, 3, 1, 1, 3, 2, 2, 1.5, 0, 0, 0, 1.5, 0, 0, 0, 1.5, 10, -5, 20, 0, 0, 0, 3, 2, 2)
    put("igtl_message", "segmentation.bin", message("IMAGE", "segmentation", image + bytes([0, 1, 1, 2, 0, 1, 1, 1, 0, 0, 2, 1])), 1)


if __name__ == "__main__":
    main()
