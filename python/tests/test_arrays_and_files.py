# SPDX-License-Identifier: GPL-3.0-or-later
"""Images, meshes, surfaces and landmarks between numpy and files; argument checks."""
import json
import math

import numpy as np
import pytest

import physreg
from conftest import skip_or_fail


def block_labels():
    """A 6×5×4-voxel volume (x, y, z) holding a 4×3×2 block of label 1 and one voxel of label 3."""
    a = np.zeros((4, 5, 6), dtype=np.uint16)  # [z, y, x]
    a[1:3, 1:4, 1:5] = 1
    a[2, 2, 2] = 3
    return a


def test_version_matches_the_program(program):
    import subprocess
    if program is None:
        skip_or_fail("no physreg program on PATH or in PHYSREG_EXECUTABLE")
    out = subprocess.run([program, "--version"], capture_output=True, text=True).stdout.strip()
    assert out == f"physreg {physreg.__version__}"


def test_label_volume_round_trip_keeps_values_order_and_geometry(tmp_path):
    labels = block_labels()
    g = physreg.ImageGeometry(origin=(-10.0, 5.0, 2.5), spacing=(0.8, 1.0, 2.5))
    physreg.write_labels(tmp_path / "l.nii.gz", labels, g)
    back, geometry = physreg.read_labels(tmp_path / "l.nii.gz")
    assert back.dtype == np.uint16 and back.shape == (4, 5, 6)
    np.testing.assert_array_equal(back, labels)
    assert geometry.size == [6, 5, 4]  # i (x), j (y), k (z)
    np.testing.assert_allclose(geometry.spacing, (0.8, 1.0, 2.5))
    np.testing.assert_allclose(geometry.origin, (-10.0, 5.0, 2.5))
    # Voxel [k=2, j=2, i=2] lies at origin + spacing * (2, 2, 2) (identity direction).
    np.testing.assert_allclose(geometry.index_to_physical((2, 2, 2)), (-8.4, 7.0, 7.5))


def test_scalar_image_and_displacement_field_round_trip(tmp_path):
    g = physreg.ImageGeometry(spacing=(2.0, 2.0, 2.0))
    image = np.arange(60, dtype=np.float32).reshape(3, 4, 5) / 7
    physreg.write_image(tmp_path / "i.nrrd", image, g)
    back, _ = physreg.read_image(tmp_path / "i.nrrd")
    np.testing.assert_array_equal(back, image)
    field = np.random.default_rng(1).normal(size=(3, 4, 5, 3)).astype(np.float32)
    physreg.write_displacement_field(tmp_path / "u.nii.gz", field, g)
    u, ug = physreg.read_displacement_field(tmp_path / "u.nii.gz")
    assert u.shape == (3, 4, 5, 3)
    np.testing.assert_array_equal(u, field)
    assert ug.size == [5, 4, 3]


def test_wrong_dtype_is_a_type_error_naming_the_argument(tmp_path):
    with pytest.raises(TypeError, match=r"labels: expected dtype uint16, got int64"):
        physreg.write_labels(tmp_path / "x.nii.gz", np.zeros((2, 2, 2), dtype=np.int64), physreg.ImageGeometry())
    with pytest.raises(TypeError, match=r"image: expected dtype float32"):
        physreg.write_image(tmp_path / "x.nii.gz", np.zeros((2, 2, 2)), physreg.ImageGeometry())
    assert not (tmp_path / "x.nii.gz").exists()


def test_wrong_shape_or_layout_is_a_value_error(tmp_path):
    g = physreg.ImageGeometry()
    with pytest.raises(ValueError, match=r"labels: expected a 3-D array indexed \[z, y, x\], got 2 dimensions"):
        physreg.write_labels(tmp_path / "x.nii.gz", np.zeros((3, 3), dtype=np.uint16), g)
    strided = np.zeros((4, 4, 4), dtype=np.uint16)[:, :, ::2]
    with pytest.raises(ValueError, match=r"C-contiguous"):
        physreg.write_labels(tmp_path / "x.nii.gz", strided, g)
    with pytest.raises(ValueError, match=r"shape \(nz, ny, nx, 3\)"):
        physreg.write_displacement_field(tmp_path / "x.nii.gz", np.zeros((2, 2, 2, 2), np.float32), g)
    assert not (tmp_path / "x.nii.gz").exists()


def test_impossible_geometry_is_refused():
    with pytest.raises(physreg.Error, match=r"spacing"):
        physreg.ImageGeometry(spacing=(1.0, -1.0, 1.0))
    with pytest.raises(physreg.Error, match=r"orthonormal"):
        physreg.ImageGeometry(direction=np.array([[1.0, 0, 0], [1.0, 1.0, 0], [0, 0, 1.0]]))


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nothing\.nii\.gz': file does not exist"):
        physreg.read_labels(tmp_path / "nothing.nii.gz")
    with pytest.raises(FileNotFoundError):
        physreg.read_mesh(tmp_path / "nothing.vtu")
    with pytest.raises(FileNotFoundError):
        physreg.read_landmarks(tmp_path / "nothing.csv")
    bad = tmp_path / "garbage.nii.gz"
    bad.write_bytes(b"this is not an image")
    with pytest.raises(physreg.Error, match=r"garbage\.nii\.gz"):
        physreg.read_labels(bad)


def test_fractional_labels_are_refused(tmp_path):
    physreg.write_image(tmp_path / "f.nii.gz", np.full((2, 2, 2), 1.5, np.float32), physreg.ImageGeometry())
    with pytest.raises(physreg.Error, match=r"f\.nii\.gz"):
        physreg.read_labels(tmp_path / "f.nii.gz")


def test_hexahedral_mesh_from_labels_matches_the_voxels():
    labels = block_labels()
    g = physreg.ImageGeometry(spacing=(2.0, 1.0, 1.5))
    mesh = physreg.mesh_from_labels(labels, g, kind="hex")
    assert mesh.cell_type == "hexahedron"
    assert mesh.cell_count == 24 and mesh.cells.shape == (24, 8)
    assert sorted(set(mesh.cell_labels.tolist())) == [1, 3]
    volumes = mesh.volume_per_label()
    assert volumes[1] == pytest.approx(23 * 3.0) and volumes[3] == pytest.approx(3.0)
    # Voxel faces: the block spans voxels i = 1…4 → x from 0.5 to 4.5 voxels × 2 mm.
    assert mesh.nodes[:, 0].min() == pytest.approx(1.0) and mesh.nodes[:, 0].max() == pytest.approx(9.0)


def test_tetrahedral_mesh_of_a_ball_has_its_volume():
    z, y, x = np.mgrid[0:30, 0:30, 0:30]
    ball = ((x - 14.5) ** 2 + (y - 14.5) ** 2 + (z - 14.5) ** 2 < 10.0 ** 2).astype(np.uint16) * 2
    mesh = physreg.mesh_from_labels(ball, physreg.ImageGeometry(), kind="tet", cell_size_mm=3.0, facet_distance_mm=0.4)
    assert mesh.cell_type == "tetrahedron" and mesh.cells.shape[1] == 4
    assert set(mesh.cell_labels.tolist()) == {2}
    assert mesh.volume_per_label()[2] == pytest.approx(4 / 3 * math.pi * 1000, rel=0.06)
    centre = mesh.nodes.mean(axis=0)
    np.testing.assert_allclose(centre, (14.5, 14.5, 14.5), atol=0.5)


def test_meshing_arguments_are_checked():
    labels = block_labels()
    with pytest.raises(ValueError, match=r"kind: 'prism' is not one of"):
        physreg.mesh_from_labels(labels, physreg.ImageGeometry(), kind="prism")
    with pytest.raises(ValueError, match=r"cell_size_mm: -1 must be a positive number"):
        physreg.mesh_from_labels(labels, physreg.ImageGeometry(), kind="tet", cell_size_mm=-1)
    with pytest.raises(physreg.Error, match=r"no label|empty|nonzero"):
        physreg.mesh_from_labels(np.zeros((3, 3, 3), np.uint16), physreg.ImageGeometry(), kind="hex")


def test_mesh_file_round_trip_and_node_views(tmp_path):
    mesh = physreg.mesh_from_labels(block_labels(), physreg.ImageGeometry(), kind="hex")
    nodes = mesh.nodes
    assert nodes.base is not None  # a view of the mesh, not a copy
    nodes[:, 2] += 10.0            # writing through the view moves the mesh
    for suffix in (".vtu", ".msh", ".v2.msh"):
        physreg.write_mesh(tmp_path / f"m{suffix}", mesh)
        back = physreg.read_mesh(tmp_path / f"m{suffix}")
        np.testing.assert_allclose(back.nodes, mesh.nodes)
        np.testing.assert_array_equal(back.cell_labels, mesh.cell_labels)
    assert physreg.read_mesh(tmp_path / "m.vtu").nodes[:, 2].min() == pytest.approx(10.5)  # block from voxel face z = 0.5 mm, moved 10 mm


def test_hausdorff_of_a_shifted_surface_is_the_shift():
    mesh = physreg.mesh_from_labels(block_labels(), physreg.ImageGeometry(), kind="hex")
    surface = physreg.boundary_surface(mesh)
    assert surface.triangles.shape[1] == 3 and surface.vertices.shape[1] == 3
    assert physreg.hausdorff(surface, surface)["max_mm"] == pytest.approx(0.0, abs=1e-12)
    shifted = physreg.Surface(surface.vertices + np.array([0.0, 0.0, 0.75]), surface.triangles.copy())
    h = physreg.hausdorff(surface, shifted)
    assert h["max_mm"] == pytest.approx(0.75, rel=1e-9)
    assert 0.0 < h["mean_mm"] <= 0.75


def test_surface_arguments_are_checked():
    v = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"triangles: row 0 names vertex 7 \(there are 3\)"):
        physreg.Surface(v, np.array([[0, 1, 7]], dtype=np.int32))
    with pytest.raises(TypeError, match=r"triangles: expected dtype int32"):
        physreg.Surface(v, np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match=r"vertices: expected shape \(N, 3\)"):
        physreg.Surface(np.zeros((3, 2)), np.array([[0, 1, 2]], dtype=np.int32))


def test_tre_of_known_offsets_and_its_checks():
    truth = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0]])
    predicted = truth + np.array([[3.0, 4, 0], [0, 0, 1], [0, 0, 0]])
    r = physreg.tre(predicted, truth)
    np.testing.assert_allclose(r["errors_mm"], [5.0, 1.0, 0.0])
    assert r["mean_mm"] == pytest.approx(2.0) and r["max_mm"] == pytest.approx(5.0) and r["count"] == 3
    with pytest.raises(ValueError, match=r"predicted: 2 points but truth has 3"):
        physreg.tre(predicted[:2], truth)
    bad = predicted.copy()
    bad[1, 1] = np.nan
    with pytest.raises(ValueError, match=r"predicted: row 1 is not finite"):
        physreg.tre(bad, truth)


def test_landmarks_round_trip_through_slicer_markups(tmp_path):
    names = ["T1", "V1", "S1"]
    positions = np.array([[1.5, -2.0, 30.0], [0.0, 0.0, 0.0], [-7.25, 4.0, 1.0]])
    physreg.write_landmarks(tmp_path / "p.mrk.json", names, positions)
    markups = json.loads((tmp_path / "p.mrk.json").read_text())
    assert markups["markups"][0]["type"] == "Fiducial"
    back_names, back, _ = physreg.read_landmarks(tmp_path / "p.mrk.json")
    assert back_names == names
    np.testing.assert_allclose(back, positions)
    physreg.write_landmarks(tmp_path / "p.csv", names, positions)
    np.testing.assert_allclose(physreg.read_landmarks(tmp_path / "p.csv")[1], positions)
    with pytest.raises(ValueError, match=r"positions: 2 positions for 3 names"):
        physreg.write_landmarks(tmp_path / "q.csv", names, positions[:2])
