# SPDX-License-Identifier: GPL-3.0-or-later
"""The program's commands from Python: results, progress callbacks, and the program's messages."""
import json

import numpy as np
import pytest

import physreg
from conftest import program_error


def test_phantom_dataset_manifest(dataset):
    manifest = json.loads((dataset / "manifest.json").read_text())
    assert manifest["format"] == "physreg-phantom-dataset"
    labels, geometry = physreg.read_labels(dataset / "rest" / "labels.nii.gz")
    assert labels.ndim == 3 and labels.max() > 0 and min(geometry.spacing) > 0


def test_register_compression_returns_its_summary_and_reports_progress(dataset, tmp_path):
    calls = []
    summary = physreg.register_compression(tmp_path / "rc", dataset=dataset, state="A", grid="12x10x6",
                                           progress=lambda label, f, message: calls.append((label, f, message)))
    assert (tmp_path / "rc" / "summary.json").exists()
    assert summary["state"] == "A" and summary["model"]["grid_cells"] == [12, 10, 6]
    assert summary["tre_against_dataset"]["all"]["count"] == 25
    assert calls and {label for label, _, _ in calls} == {"register-compression"}
    fractions = [f for _, f, _ in calls]
    assert all(0.0 <= f <= 1.0 for f in fractions) and fractions == sorted(fractions)


def test_summary_tre_equals_tre_recomputed_from_the_written_landmarks(dataset, tmp_path):
    summary = physreg.register_compression(tmp_path / "rc", dataset=dataset, state="A", grid="12x10x6", quiet=True)
    names, predicted, _ = physreg.read_landmarks(tmp_path / "rc" / "landmarks.csv")
    truth_names, truth, _ = physreg.read_landmarks(dataset / "states" / "A" / "landmarks.csv")
    order = [truth_names.index(n) for n in names]
    mine = physreg.tre(predicted, truth[order])
    theirs = summary["tre_against_dataset"]["all"]
    assert mine["count"] == theirs["count"]
    assert mine["mean_mm"] == pytest.approx(theirs["mean_mm"], abs=1e-3)  # landmarks.csv holds 4 decimals
    assert mine["max_mm"] == pytest.approx(theirs["max_mm"], abs=1e-3)
    # And through `physreg evaluate` (files, name matching, per type).
    report = physreg.evaluate(tmp_path / "rc" / "landmarks.csv", dataset / "states" / "A" / "landmarks.csv", tmp_path / "ev", quiet=True)
    assert report["all"]["mean_mm"] == pytest.approx(mine["mean_mm"], abs=1e-9)
    assert (tmp_path / "ev" / "tre.csv").exists() and (tmp_path / "ev" / "tre.png").exists()


def test_register_surface_reports_tre_and_hausdorff(dataset, tmp_path):
    summary = physreg.register_surface(tmp_path / "rs", dataset=dataset, visible=50, cell_size=10,
                                       max_steps_per_plateau=20, quiet=True)
    assert set(summary["methods"]) == {"at_rest", "biomechanical", "adjoint", "rigid", "icp"}
    assert summary["method"] == "adjoint"
    text = json.dumps(summary).lower()
    assert "hausdorff" in text and "tre" in text
    mesh = physreg.read_mesh(tmp_path / "rs" / "mesh.vtu")
    assert mesh.cell_type == "tetrahedron" and mesh.node_count > 10


def test_register_images_biomechanical_with_label_baselines(dataset, tmp_path):
    summary = physreg.register_images(tmp_path / "ri", dataset=dataset, cycles=2, cell_size=8,
                                      baselines="labels", quiet=True)
    # The initial rigid alignment (default) is computed; it is applied, and then reported as a
    # method of its own, only when it removes more than half of the boundary distance (a dataset's
    # states share one frame, so it usually is not).
    a = summary["initial_alignment"]
    assert a["mode"] == "rigid" and a["decision"]
    before = a["boundary_rms_distance_mm"]["before"]
    assert a["applied"] == (before - a["boundary_rms_distance_mm"]["after"] > a["min_reduction"] * before)
    expected = {"at_rest", "biomechanical", "rigid_labels", "demons_labels", "bspline_labels"} | ({"initial_alignment"} if a["applied"] else set())
    assert set(summary["methods"]) == expected
    assert all(m["status"] == "ok" for m in summary["methods"].values())
    # This pair (the insufflation) barely moves the labels: at rest every Dice is already 1 and the
    # landmarks move 0.25 mm. What can fail here is a registration that makes it worse; accuracy
    # itself is checked on the push (test_image_pipeline.py, test_cli.sh: TRE <= 0.7x at rest).
    bio, rest = summary["methods"]["biomechanical"], summary["methods"]["at_rest"]
    assert set(bio["dice"]) == set(rest["dice"]) and len(bio["dice"]) >= 2
    for label, d in bio["dice"].items():
        assert d >= rest["dice"][label] - 0.01, (label, bio["dice"], rest["dice"])
    assert bio["tre"]["all"]["mean_mm"] <= rest["tre"]["all"]["mean_mm"] + 0.05, (bio["tre"]["all"], rest["tre"]["all"])
    assert all(e > 0 for e in summary["estimated_moduli_pa"].values())
    u, g = physreg.read_displacement_field(tmp_path / "ri" / "displacement.nii.gz")
    assert u.shape[-1] == 3 and np.isfinite(u).all()


def test_simulate_a_case_on_a_mesh_made_in_python(tmp_path):
    labels = np.zeros((6, 6, 10), dtype=np.uint16)
    labels[1:5, 1:5, 1:9] = 1
    mesh = physreg.mesh_from_labels(labels, physreg.ImageGeometry(spacing=(4.0, 4.0, 4.0)), kind="hex")
    physreg.write_mesh(tmp_path / "bar.vtu", mesh)
    (tmp_path / "case.yaml").write_text(f"""
mesh: {tmp_path / 'bar.vtu'}
solver: {{mode: static, load_steps: 2}}
constraints:
  - {{name: root, select: {{face: x_min, tolerance_mm: 1}}, fixed: [x, y, z]}}
  - {{name: pull, select: {{face: x_max, tolerance_mm: 1}}, displacement_mm: [2, 0, 0]}}
output: {{directory: unused, frames: 1}}
""")
    summary = physreg.simulate(tmp_path / "case.yaml", output=tmp_path / "sim", quiet=True)
    assert summary["max_displacement_mm"] == pytest.approx(2.0, rel=1e-6)
    assert (tmp_path / "sim" / "final.vtu").exists() and not (tmp_path / "unused").exists()


def test_errors_carry_the_programs_message_and_leave_no_output(dataset, tmp_path, program):
    with pytest.raises(physreg.Error) as python_error:
        physreg.register_images(tmp_path / "bad", dataset=dataset, method="affine", quiet=True)
    assert "--method 'affine'" in str(python_error.value)
    assert not (tmp_path / "bad").exists()
    if program is not None:
        assert program_error(program, "register-images", "--dataset", dataset, "--method", "affine", "-o", tmp_path / "bad") == str(python_error.value)


def test_command_line_mistakes_are_errors(tmp_path):
    with pytest.raises(physreg.Error, match=r"command line: A subcommand is required"):  # as the program says
        physreg.run("frobnicate")
    with pytest.raises(physreg.Error, match=r"command line: .*--no-such-option"):
        physreg.run("mesh", tmp_path / "x.nii.gz", output=tmp_path / "m.vtu", no_such_option=True)
    with pytest.raises(TypeError, match=r"needs output="):
        physreg.register_images(None, dataset=tmp_path)


def test_missing_dataset_is_file_not_found(tmp_path):
    with pytest.raises((FileNotFoundError, physreg.Error), match=r"no_dataset"):
        physreg.register_compression(tmp_path / "out", dataset=tmp_path / "no_dataset", state="A", quiet=True)
    assert not (tmp_path / "out").exists()


def test_an_exception_in_the_progress_callback_stops_the_command(dataset, tmp_path):
    def stop(label, fraction, message):
        if fraction > 0.2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        physreg.register_compression(tmp_path / "stopped", dataset=dataset, state="A", grid="12x10x6", progress=stop)
    assert not (tmp_path / "stopped").exists()


def test_the_example_script_runs_on_a_dataset_and_draws_its_plot(dataset, tmp_path):
    import runpy
    import os
    example = os.path.join(os.environ.get("PHYSREG_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", "..")),
                           "examples", "01_compression.py")
    module = runpy.run_path(example)
    result, at_rest = module["main"](tmp_path, dataset, "A")
    assert (tmp_path / "tre_A.png").stat().st_size > 10_000
    assert result["count"] == 25 and at_rest["count"] == 25


def test_enrichment_database_built_and_applied_from_python(dataset, tmp_path):
    physreg.enrich_build(tmp_path / "db.phe", dataset=dataset, positions="A", depths="4,6", grid="16x12x8", coarse_grid="8x6x4", quiet=True)
    assert (tmp_path / "db.phe").stat().st_size > 0
    summary = physreg.enrich_apply(tmp_path / "c2f", database=tmp_path / "db.phe", dataset=dataset, state="A", grid="16x12x8", quiet=True)
    assert summary["tre_against_dataset"]["all"]["count"] == 25
    assert (tmp_path / "c2f" / "coarse.vtu").exists() and (tmp_path / "c2f" / "report.html").exists()
    with pytest.raises(physreg.Error, match=r"built for another fine mesh"):
        physreg.enrich_apply(tmp_path / "bad", database=tmp_path / "db.phe", dataset=dataset, state="A", grid="14x12x8", quiet=True)
    assert not (tmp_path / "bad").exists()
