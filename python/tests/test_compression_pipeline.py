# SPDX-License-Identifier: GPL-3.0-or-later
"""Paper 000 as library functions (issue 43): register-compression, estimate and enrich apply on
the command line and predict_compression, estimate_compression and predict_coarse_to_fine in Python
call the same functions with the same settings and give the same answer. The case is the small
phantom's compression A (a sphere pressed 6 mm into the body over the liver)."""
import json

import numpy as np
import pytest

import physreg

GRID = "27x20x13"


@pytest.fixture(scope="module")
def through_the_command(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("rc_pipeline") / "cmd"
    summary = physreg.register_compression(out, dataset=dataset, state="A", grid=GRID, quiet=True)
    return out, summary


@pytest.fixture(scope="module")
def subject(dataset):
    return physreg.CompressionSubject.from_dataset(dataset, grid=GRID)


def test_python_and_the_command_give_the_same_prediction(dataset, through_the_command, subject):
    out, summary = through_the_command
    r = physreg.predict_compression(subject, physreg.CompressionCase.from_dataset(dataset, "A"))
    field_file, geometry = physreg.read_displacement_field(out / "displacement.nii.gz")
    field_memory, same = r.field
    assert field_memory.shape == field_file.shape
    assert np.allclose(same.origin, geometry.origin) and np.allclose(same.spacing, geometry.spacing)
    assert np.max(np.abs(field_memory.astype(np.float64) - field_file)) <= 1e-9
    assert np.max(np.abs(field_memory)) > 1.0  # the tool moved the model
    assert summary["settings"] == r.settings == r.summary["settings"]
    assert summary["settings"]["grid"] == GRID and summary["settings"]["solver"] == "relaxation"
    assert summary["tre_against_dataset"] == r.summary["tre_against_dataset"]
    # The model lands nearer the truth than the landmarks left at rest, by a real margin.
    model, rest = summary["tre_against_dataset"]["all"]["mean_mm"], summary["tre_landmarks_at_rest"]["all"]["mean_mm"]
    assert model < 0.8 * rest, (model, rest)
    names, positions = physreg.read_landmarks(out / "landmarks.csv")[:2]
    for name, p in zip(names, positions):
        assert np.allclose(r.landmarks[name], p, atol=1e-6)


def test_a_settings_file_gives_the_command_line_answer(dataset, through_the_command, tmp_path):
    out, summary = through_the_command
    settings = tmp_path / "model.yaml"
    settings.write_text(f"grid: {GRID}\ntool_speed: 0.01\n")
    again = physreg.register_compression(tmp_path / "f", dataset=dataset, state="A", settings=settings, quiet=True)
    assert again["settings"] == summary["settings"]
    assert again["tre_against_dataset"] == summary["tre_against_dataset"]


def test_the_model_belongs_to_the_subject(dataset, subject):
    case = physreg.CompressionCase.from_dataset(dataset, "A")
    with pytest.raises(physreg.Error, match="variant: the model was built with other values"):
        physreg.predict_compression(subject, case, variant="homogeneous")
    with pytest.raises(physreg.Error, match="did you mean 'tool_speed'"):
        physreg.predict_compression(subject, case, tool_sped=0.02)
    with pytest.raises(physreg.Error, match="tool_speed 0.9 cells must be in"):
        physreg.predict_compression(subject, case, tool_speed=0.9)


def test_a_tool_from_python_with_its_truth(dataset, subject):
    """A user's tool: the dataset's path handed over as arrays, the truth as a dict."""
    manifest = json.loads((dataset / "manifest.json").read_text())
    state = next(s for s in manifest["states"] if s["name"] == "A")
    tool = state["tool"]
    path = np.array([tool["contact_position_mm"], tool["final_position_mm"]], dtype=float)
    names, positions = physreg.read_landmarks(dataset / state["files"]["landmarks"])[:2]
    truth = {n: tuple(p) for n, p in zip(names, positions)}
    case = physreg.CompressionCase(physreg.Tool(path, tool["radius_mm"]), truth=truth, name="A")
    r = physreg.register_compression(subject, case)  # the mode's one name: in memory, given the subject
    assert isinstance(r, physreg.CompressionRegistration)
    reference = physreg.predict_compression(subject, physreg.CompressionCase.from_dataset(dataset, "A"))
    assert r.summary["tre_against_dataset"]["all"]["mean_mm"] == pytest.approx(reference.summary["tre_against_dataset"]["all"]["mean_mm"], abs=1e-6)


def test_estimation_from_python_and_the_command_agree(dataset, tmp_path):
    settings = dict(train="A", validate="none", grid=GRID, max_evaluations=2)
    fit = physreg.estimate_compression(dataset, **settings)
    physreg.run("estimate", dataset=dataset, train="A", validate="none", grid=GRID, max_evaluations=2, output=tmp_path / "p.json",
                report=tmp_path / "report.json")
    command = json.loads((tmp_path / "report.json").read_text())
    assert fit.summary["fitted"] == command["fitted"]
    assert fit.summary["objective_mm"] == command["objective_mm"]
    fit.write_parameters(tmp_path / "q.json")
    subject = physreg.CompressionSubject.from_dataset(dataset, parameters=str(tmp_path / "q.json"))
    assert subject.parameters == fit.fitted
    with pytest.raises(physreg.Error, match="drop grid"):
        physreg.CompressionSubject.from_dataset(dataset, parameters=str(tmp_path / "q.json"), grid=GRID)


def test_the_specifications_are_published(program):
    for mode in ("register-compression", "estimate", "enrich-build", "enrich-apply"):
        spec = physreg.settings_spec(mode)
        assert spec["variant"]["default"] == "coupled" and spec["grid"]["kind"] == "text"
    assert "condensed" in physreg.settings_spec("register-compression")["solver"]["choices"]
    assert "condensed" not in physreg.settings_spec("estimate")["solver"]["choices"]
