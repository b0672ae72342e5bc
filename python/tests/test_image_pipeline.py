# SPDX-License-Identifier: GPL-3.0-or-later
"""The registration pipelines as library functions (issue 43): the commands (register-images,
register-surface), a settings file and Python (register_image_pair, register_partial_surface) call
the same function with the same settings and give the same answer. The case is the small phantom's
large local push (a 15 mm sphere pressed 30 mm into the right lobe: 3.2 mm mean TRE at rest), where
a registration has something to find; the session's small phantom barely deforms (0.25 mm)."""
import json

import numpy as np
import pytest

import physreg

SMALL = dict(cycles=4, cell_size=8.0, baselines="none")


@pytest.fixture(scope="module")
def push(tmp_path_factory):
    out = tmp_path_factory.mktemp("push") / "ph"
    physreg.phantom(out, preset="small", seed=2, materials="healthy", organs_only=True, depths="5", no_calculix=True,
                    insufflation_pa=0, push_depth=30, push_tool_radius=15, quiet=True)
    return out


@pytest.fixture(scope="module")
def through_the_command(push, tmp_path_factory):
    out = tmp_path_factory.mktemp("ri_pipeline") / "cmd"
    summary = physreg.register_images(out, dataset=push, state="push", quiet=True, **SMALL)
    return out, summary


@pytest.fixture(scope="module")
def in_memory(push):
    pair = physreg.ImagePair.from_dataset(push, "push")
    assert pair.has_landmarks
    r = physreg.register_images(pair, **SMALL)  # the mode's one name: in memory, given an ImagePair
    assert isinstance(r, physreg.ImageRegistration)
    return r


def test_python_and_the_command_give_the_same_field(through_the_command, in_memory):
    out, summary = through_the_command
    field_file, geometry = physreg.read_displacement_field(out / "displacement.nii.gz")
    field_memory, same = in_memory.field()
    assert field_memory.shape == field_file.shape and field_memory.dtype == np.float32
    assert np.allclose(same.origin, geometry.origin) and np.allclose(same.spacing, geometry.spacing)
    # The same function on the same data with the same settings: equal to 1e-9 mm (the file is
    # float32, so equality means the same float32 values).
    assert np.max(np.abs(field_memory.astype(np.float64) - field_file)) <= 1e-9
    assert np.max(np.abs(field_memory)) > 0.5
    # The same settings, written from the specification by both routes.
    assert summary["settings"] == in_memory.settings == in_memory.summary["settings"]
    assert summary["settings"]["rms_tolerance"] == 0.001 and summary["settings"]["rest_offsets"] is True
    assert summary["settings"]["hold"] == "none"  # a dataset's hold=auto (no support assumed since issue 46)
    tre_file = summary["methods"]["biomechanical"]["tre"]["all"]["mean_mm"]
    tre_memory = in_memory.summary["methods"]["biomechanical"]["tre"]["all"]["mean_mm"]
    assert abs(tre_file - tre_memory) <= 1e-9
    # The carried landmarks are the command's landmarks.csv.
    names, positions = physreg.read_landmarks(out / "landmarks.csv")[:2]
    carried = in_memory.landmarks
    assert len(carried) == len(names) == 25
    for name, p in zip(names, positions):
        assert np.allclose(carried[name], p, atol=1e-4)


def test_the_default_registration_is_accurate(in_memory):
    """Not existence: the biomechanical answer beats leaving the organs at rest by a margin (measured
    2026-11-28 with the posterior faces held: TRE 2.01 against 3.23 mm, liver Dice 0.968 against 0.933,
    tumour 0.930 against 0.649; with hold none, the default since issue 46, the same push of seed 2
    gave TRE 1.91 against 3.10 at rest (1.88 held), liver Dice 0.966, tumour 0.919)."""
    methods = in_memory.summary["methods"]
    rest, bio = methods["at_rest"], methods["biomechanical"]
    assert bio["tre"]["all"]["mean_mm"] <= 0.7 * rest["tre"]["all"]["mean_mm"], (bio["tre"]["all"], rest["tre"]["all"])
    liver, tumour = "2", "3"  # the small preset's labels
    assert bio["dice"][liver] >= rest["dice"][liver] + 0.02, (bio["dice"], rest["dice"])
    assert bio["dice"][tumour] >= rest["dice"][tumour] + 0.15, (bio["dice"], rest["dice"])


def test_a_settings_file_gives_the_same_settings(push, tmp_path, in_memory):
    settings = tmp_path / "settings.yaml"
    settings.write_text("cycles: 4\ncell_size: 8.0\nbaselines: none\n")
    summary = physreg.register_images(tmp_path / "from_file", dataset=push, state="push", settings=settings, quiet=True)
    assert summary["settings"] == in_memory.settings
    assert summary["settings_file"] == str(settings)
    # The command line wins over the file.
    summary = physreg.register_images(tmp_path / "override", dataset=push, state="push", settings=settings, cycles=1, quiet=True)
    assert summary["settings"]["cycles"] == 1 and summary["settings"]["cell_size"] == 8.0


def test_settings_are_checked_by_the_specification(dataset, tmp_path):
    pair = physreg.ImagePair.from_dataset(dataset, "insufflation")
    with pytest.raises(physreg.Error, match="unknown key 'cycels'.*did you mean 'cycles'"):
        physreg.register_image_pair(pair, cycels=3)
    with pytest.raises(physreg.Error, match=r"cell_size 0 mm must be > 0"):
        physreg.register_image_pair(pair, settings={"cell_size": 0})
    with pytest.raises(physreg.Error, match="method 'affine': use biomechanical, rigid, demons or bspline"):
        physreg.register_image_pair(pair, method="affine")
    bad = tmp_path / "bad.yaml"
    bad.write_text("cell_size: big\n")
    with pytest.raises(physreg.Error, match="bad.yaml: cell_size: expected a number"):
        physreg.register_images(tmp_path / "bad", dataset=dataset, settings=bad, quiet=True)
    assert not (tmp_path / "bad").exists()
    spec = physreg.settings_spec("register-images")
    assert spec["rms_tolerance"]["default"] == 0.001 and spec["rms_tolerance"]["unit"] == "mm"
    assert spec["method"]["choices"] == ["biomechanical", "rigid", "demons", "bspline"]
    assert spec["estimate_moduli"]["option"] == "--no-moduli"


def test_a_pair_from_arrays(push):
    """Arrays as a user holds them: the dataset's rest and state images, landmarks as a dict."""
    manifest = json.loads((push / "manifest.json").read_text())
    states = {s["name"]: s for s in manifest["states"]}
    rest, state = states["rest"]["files"], states["push"]["files"]
    fixed, fg = physreg.read_image(push / state["intensity"])
    fixed_labels, _ = physreg.read_labels(push / state["labels"])
    moving, mg = physreg.read_image(push / rest["intensity"])
    moving_labels, _ = physreg.read_labels(push / rest["labels"])
    organs = sorted({l for role in ("liver", "lesion", "vessel", "kidney") for l in manifest["label_roles"].get(role, [])})

    def landmarks(path):
        names, positions = physreg.read_landmarks(path)[:2]
        return {n: tuple(p) for n, p in zip(names, positions)}

    pair = physreg.ImagePair(fixed, fixed_labels, fg, moving, moving_labels, mg,
                             landmarks_fixed=landmarks(push / state["landmarks"]),
                             landmarks_moving=landmarks(push / rest["landmarks"]), auto_hold="posterior")
    r = physreg.register_image_pair(pair, structures=organs, **SMALL)
    assert r.method == "biomechanical" and r.methods[:2] == ["at_rest", "biomechanical"]
    methods = r.summary["methods"]
    assert methods["biomechanical"]["tre"]["all"]["mean_mm"] < methods["at_rest"]["tre"]["all"]["mean_mm"]
    warped, geometry = r.warped_labels
    assert warped.dtype == np.uint16 and warped.shape == tuple(reversed(geometry.size))
    with pytest.raises(ValueError, match="give both or neither"):
        physreg.ImagePair(fixed, fixed_labels, fg, moving, moving_labels, mg, landmarks_fixed={"a": (0, 0, 0)})
    # The label maps alone (issue 57: a label-to-label pair): the biomechanical method never reads
    # intensities, so its answer is the same to the bit; intensity baselines are refused.
    labels_only = physreg.ImagePair(None, fixed_labels, fg, None, moving_labels, mg,
                                    landmarks_fixed=landmarks(push / state["landmarks"]),
                                    landmarks_moving=landmarks(push / rest["landmarks"]), auto_hold="posterior")
    same = physreg.register_image_pair(labels_only, structures=organs, **SMALL)
    assert same.summary["intensities"] is False and r.summary["intensities"] is True
    assert same.summary["methods"]["biomechanical"]["tre"]["all"] == methods["biomechanical"]["tre"]["all"]
    assert np.array_equal(same.field()[0], r.field()[0])
    with pytest.raises(physreg.Error, match="--baselines intensity needs the --fixed and --moving images"):
        physreg.register_image_pair(labels_only, structures=organs, **dict(SMALL, baselines="intensity"))
    with pytest.raises(ValueError, match="give both images or neither"):
        physreg.ImagePair(fixed, fixed_labels, fg, None, moving_labels, mg)


# ---- paper 001 -----------------------------------------------------------------------------------

SURFACE = dict(cell_size=10.0)


@pytest.fixture(scope="module")
def surface_through_the_command(push, tmp_path_factory):
    out = tmp_path_factory.mktemp("rs_pipeline") / "cmd"
    summary = physreg.register_surface(out, dataset=push, state="push", quiet=True, **SURFACE)
    return out, summary


@pytest.fixture(scope="module")
def surface_in_memory(push):
    case = physreg.PartialSurfaceCase.from_dataset(push, "push", **SURFACE)
    return case, physreg.register_partial_surface(case, **SURFACE)


def test_paper001_python_and_the_command_give_the_same_field(surface_through_the_command, surface_in_memory):
    out, summary = surface_through_the_command
    case, result = surface_in_memory
    field_file, geometry = physreg.read_displacement_field(out / "displacement.nii.gz")
    field_memory, same = result.field(case)
    assert field_memory.shape == field_file.shape
    assert np.allclose(same.origin, geometry.origin) and np.allclose(same.spacing, geometry.spacing)
    assert np.max(np.abs(field_memory.astype(np.float64) - field_file)) <= 1e-9
    assert np.max(np.abs(field_memory)) > 0.5
    assert summary["settings"] == result.settings == result.summary["settings"]
    assert summary["settings"]["support"] == "auto" and summary["support"] == result.summary["support"] and summary["settings"]["cell_size"] == 10.0
    for name in ("at_rest", "rigid", "icp", "biomechanical"):
        assert abs(summary["methods"][name]["tre"]["all"]["mean_mm"] - result.summary["methods"][name]["tre"]["all"]["mean_mm"]) <= 1e-9


def test_paper001_default_registration_is_accurate(surface_in_memory):
    """The default answer (the adjoint method, issue 56) and the biomechanical one beside it beat
    leaving the liver at rest by a margin, and fit the cloud (measured 2026-11-28 with 7 mm cells:
    biomechanical TRE 1.01 against 3.23 mm at rest)."""
    _, result = surface_in_memory
    methods = result.summary["methods"]
    rest = methods["at_rest"]
    for name in ("adjoint", "biomechanical"):
        m = methods[name]
        assert m["tre"]["all"]["mean_mm"] <= 0.7 * rest["tre"]["all"]["mean_mm"], (name, m["tre"]["all"], rest["tre"]["all"])
        assert m["cloud_to_model_mm"]["mean"] < rest["cloud_to_model_mm"]["mean"]
    assert result.method == "adjoint" and result.displacement().shape == (result.summary["model"]["nodes"], 3)
    assert result.displacement("rigid").shape == result.displacement().shape
    assert len(result.landmarks) == 25


def test_paper001_settings_are_checked(dataset):
    case = physreg.PartialSurfaceCase.from_dataset(dataset, "insufflation", visible=50, **SURFACE)
    with pytest.raises(physreg.Error, match="noise -1 mm must be ≥ 0"):
        physreg.register_partial_surface(case, noise=-1.0)  # 0: estimated from the cloud
    with pytest.raises(physreg.Error, match="unknown key 'd9'.*did you mean 'd90'"):
        physreg.register_partial_surface(case, d9=4.0)
    with pytest.raises(physreg.Error, match="tool_path '1,nan,3': a coordinate is not finite"):
        physreg.register_partial_surface(case, tool_path="1,nan,3", tool_radius=5.0)
    with pytest.raises(physreg.Error, match="tool_radius 5 mm: no tool_path to go with it"):
        physreg.register_partial_surface(case, tool_radius=5.0)
    with pytest.raises(FileNotFoundError, match="--load-points '/nonexistent/tool.csv': file does not exist"):
        physreg.register_partial_surface(case, load_points="/nonexistent/tool.csv")
    spec = physreg.settings_spec("register-surface")
    assert spec["support"]["choices"] == ["auto", "posterior", "springs", "none"] and spec["d90"]["default"] == 5.0


def test_paper001_safeguard_keeps_an_answer_that_fits_by_stretching(surface_through_the_command):
    """Issue 46 item 5, the other side: the cloud is the model's front moved 12 mm sideways, a motion
    the posterior supports forbid the rigid fits to follow (their starts are judged by the supports)
    but the biomechanical model reaches by stretching. It fits the cloud better than the rigid fit and
    at rest, so nothing is flagged and it stays the answer."""
    out, _ = surface_through_the_command
    model = physreg.SurfaceModel.from_mesh(physreg.read_mesh(out / "mesh.vtu"))
    nodes = model.mesh.nodes
    surface = np.unique(model.surface_triangles)
    front = surface[nodes[surface, 1] < np.median(nodes[surface, 1])]  # LPS: anterior is −y
    # Held at the back, as asked: the cloud (the front only) cannot refute it.
    case = physreg.PartialSurfaceCase(model, nodes[front] + np.array([12.0, 0.0, 0.0]), patient_frame=True)
    r = physreg.register_partial_surface(case, method="biomechanical", support="posterior", **SURFACE)
    assert r.summary["support"] == "posterior", r.summary["support_hypotheses"]
    guard = r.summary["safeguard"]
    fits = {name: m["cloud_to_model_mm"]["mean"] for name, m in r.summary["methods"].items()}
    assert fits["biomechanical"] < min(fits["rigid"], fits["at_rest"]), fits
    assert guard["flags"] == [] and guard["answer"] == "biomechanical" and r.method == "biomechanical", guard


def test_paper001_the_cloud_shows_where_the_organ_did_not_move(surface_in_memory):
    """Issue 56 item 3: on a sparse cloud over most of the surface, the parts that did not move are
    observed. The push (a 15 mm sphere 30 mm into the right lobe, the truth the phantom's own
    Mooney-Rivlin tetrahedra held at the back): most cloud points lie on the model at rest; the
    surface nodes near them and away from every moved point are the 'still' hypothesis, tried first
    and kept once it fits to the noise. Measured 2026-12-06: 229 of 1 005 nodes held, internal TRE
    1.18 mm against 2.21 at rest."""
    _, r = surface_in_memory
    decision = r.summary["support_hypotheses"]
    first = decision["hypotheses"][0]
    assert first["name"] == "still" and decision["chosen"] == "still", decision
    source = first["sources"][0]
    assert source["still_points"] > source["moved_points"] > 0, source
    surface_nodes = r.summary["model"]["surface_triangles"] // 2 + 2  # a closed surface of genus 0: V = F/2 + 2
    assert surface_nodes > first["nodes"] >= 0.1 * surface_nodes, (first["nodes"], surface_nodes)
    assert "unmoved" in first["why"] and "still supports reached the noise level" in decision["reason"], decision
    assert r.summary["supports"]["kind"] == "held" and len(r.summary["supports"]["nodes"]) == first["nodes"]
    tre = {k: m["tre"]["internal"]["mean_mm"] for k, m in r.summary["methods"].items()}
    assert tre[r.method] < 0.6 * tre["at_rest"], tre


def _moved_rigidly(surface_through_the_command, shift, front_only, patient_frame=True):
    """A case in a patient frame whose cloud is the model's surface (or its front, LPS −y) moved by
    `shift` mm, with 12 interior nodes as landmarks whose truth is the same rigid motion."""
    out, _ = surface_through_the_command
    model = physreg.SurfaceModel.from_mesh(physreg.read_mesh(out / "mesh.vtu"))
    nodes = model.mesh.nodes
    surface = np.unique(model.surface_triangles)
    seen = surface[nodes[surface, 1] < np.median(nodes[surface, 1])] if front_only else surface
    inside = np.setdiff1d(np.arange(len(nodes)), surface)[::5][:12]
    rest = {f"n{i}": tuple(nodes[i]) for i in inside}
    truth = {f"n{i}": tuple(nodes[i] + np.asarray(shift)) for i in inside}
    return physreg.PartialSurfaceCase(model, nodes[seen] + np.asarray(shift), landmarks=rest, truth=truth, patient_frame=patient_frame)


def test_paper001_a_support_that_needs_more_strain_energy_to_fit_a_patch_gives_way(surface_through_the_command):
    """Issue 56 item 3: the forces that fit a patch are not equally plausible under every support. The
    cloud is the model's front moved 6 mm to the patient's left, the whole organ with it (the truth is
    this rigid motion, not a model of ours). Held at the back, the organ fits the front by shearing; on
    springs it fits as well by translating, with a fraction of the strain energy. In a patient frame
    both are tried (the posterior guess no longer ends the search once it fits), and the springs win
    by their energy: their run places the interior closer. (What is written is then the safeguard's
    call: here the model at rest, as the rigid and deformable answers fit alike 2.4 mm apart.)
    With ν 0.45: at the default 0.48 the sheared posterior fit misses the front by 0.28 mm against
    0.18 mm and is left out by the fit alone, before any energy is weighed."""
    case = _moved_rigidly(surface_through_the_command, [6.0, 0.0, 0.0], front_only=True)
    r = physreg.register_partial_surface(case, **{**SURFACE, "poisson": 0.45})
    decision = r.summary["support_hypotheses"]
    tried = {h["name"]: h for h in decision["hypotheses"]}
    assert list(tried) == ["posterior", "springs"] and decision["chosen"] == "springs", decision
    fits = {k: h["cloud_to_model_mm"]["mean"] for k, h in tried.items()}
    assert fits["springs"] <= max(fits["posterior"] * 1.1, fits["posterior"] + 0.1), fits  # alike, or the springs closer
    assert tried["springs"]["strain_energy_mj"] < 0.9 * tried["posterior"]["strain_energy_mj"], tried
    assert "strain energy" in decision["reason"], decision["reason"]
    tre = {k: h["tre"]["all"]["mean_mm"] for k, h in tried.items()}
    assert tre["springs"] < min(tre["posterior"], 0.5 * 6.0), tre
    assert any("strain energy" in n and "posterior" in n for n in r.summary["notes"]), r.summary["notes"]
    assert not any("contradict" in n for n in r.summary["notes"]), r.summary["notes"]  # the posterior fit was not refuted


def test_paper001_supports_the_data_contradict_are_left_out(surface_through_the_command):
    """Issue 46 item 3: the supports are hypotheses chosen by the data. The cloud is the whole surface
    moved 10 mm to the patient's left, the posterior surface with it, so holding that surface cannot
    fit the cloud (measured 2026-11-28: held, 1.08 mm from the cloud and TRE 4.1 mm; springs,
    0.18 mm and 0.79 mm). In a patient frame the posterior hypothesis is tried first, fits worse than a
    looser one by more than the data resolve, and is left out with a note naming it; the looser
    answer follows the motion inside the organ. Outside a patient frame it is not offered at all."""
    case = _moved_rigidly(surface_through_the_command, [10.0, 0.0, 0.0], front_only=False)
    r = physreg.register_partial_surface(case, **SURFACE)
    decision = r.summary["support_hypotheses"]
    tried = {h["name"]: h for h in decision["hypotheses"]}
    assert [h["name"] for h in decision["hypotheses"]] == ["posterior", "springs"] and decision["chosen"] == "springs", decision
    assert tried["posterior"]["cloud_to_model_mm"]["mean"] > tried[decision["chosen"]]["cloud_to_model_mm"]["mean"] + 0.1, decision
    assert r.summary["support"] == decision["chosen"]
    # The cloud's halves are held as the answer was: springs at every node, as stiff (a first version ran them free).
    halves = r.summary["uncertainty"]
    assert halves["supports"] == "springs" and halves["support_nodes"] == r.summary["model"]["nodes"], halves
    assert halves["support_stiffness_n_per_mm"] == pytest.approx(r.summary["supports"]["stiffness_n_per_mm"]) and halves["support_stiffness_n_per_mm"] > 0
    assert halves["resolved"], halves
    assert any("contradict the posterior supports" in n for n in r.summary["notes"]), r.summary["notes"]
    methods = r.summary["methods"]
    assert methods["at_rest"]["tre"]["all"]["mean_mm"] == pytest.approx(10.0)
    assert methods["biomechanical"]["tre"]["all"]["mean_mm"] <= 1.5, methods["biomechanical"]["tre"]
    assert tried["posterior"]["tre"]["all"]["mean_mm"] > 2.0 * methods["biomechanical"]["tre"]["all"]["mean_mm"]
    free = physreg.register_partial_surface(_moved_rigidly(surface_through_the_command, [10.0, 0.0, 0.0], front_only=False, patient_frame=False), **SURFACE)
    assert "posterior" not in [h["name"] for h in free.summary["support_hypotheses"]["hypotheses"]]


def test_paper001_safeguard_leaves_a_sound_answer_alone(surface_in_memory):
    _, result = surface_in_memory
    guard = result.summary["safeguard"]
    assert guard["flags"] == [] and guard["answer"] == guard["requested"] == "adjoint", guard
    assert guard["runner_up"] in ("at_rest", "rigid") and guard["margin_mm"] > 0, guard


def test_paper001_the_cloud_halves_resolve_the_push_and_not_noise(surface_in_memory, surface_through_the_command):
    """Issue 46 item 5: the cloud's two random halves are registered apart. On the push they agree
    (their spread is a fraction of the motion, and the precision at the targets is reported); on a
    cloud that is the model's own front jittered by 1 mm noise, with nothing moved, each half chases
    its own noise: the motion is not resolved, the answer is flagged and the model at rest written."""
    _, result = surface_in_memory
    halves = result.summary["uncertainty"]
    assert halves["run"] and halves["resolved"], halves
    assert halves["spread_mm"] < 0.75 * halves["motion_mm"] and halves["precision_mm"] == pytest.approx(0.5 * halves["spread_mm"])
    assert len(halves["targets"]) == 25 and all(t["precision_mm"] >= 0 for t in halves["targets"])
    assert sum(halves["points_per_half"]) == result.summary["cloud"]["points"]
    out, _ = surface_through_the_command
    model = physreg.SurfaceModel.from_mesh(physreg.read_mesh(out / "mesh.vtu"))
    nodes = model.mesh.nodes
    surface = np.unique(model.surface_triangles)
    front = surface[nodes[surface, 1] < np.median(nodes[surface, 1])]
    noisy = nodes[front] + np.random.default_rng(5).normal(0.0, 1.0, (len(front), 3))
    # The halves judge the biomechanical answer (they are registered by it).
    r = physreg.register_partial_surface(physreg.PartialSurfaceCase(model, noisy), method="biomechanical", **SURFACE)
    halves = r.summary["uncertainty"]
    guard = r.summary["safeguard"]
    assert halves["run"] and not halves["resolved"], halves
    assert any("do not resolve the motion" in f for f in guard["flags"]) and guard["answer"] == "at_rest", guard
    off = physreg.register_partial_surface(physreg.PartialSurfaceCase(model, noisy), uncertainty="none", method="biomechanical", **SURFACE)
    assert not off.summary["uncertainty"]["run"]


def test_paper001_repeated_cloud_points_are_left_out_and_said(surface_through_the_command):
    """Issue 46's bad input: a cloud that gives points twice (a scanner's overlapping sweeps) is
    registered as the cloud without the repeats — the same answer — and a note says how many."""
    out, _ = surface_through_the_command
    model = physreg.SurfaceModel.from_mesh(physreg.read_mesh(out / "mesh.vtu"))
    nodes = model.mesh.nodes
    surface = np.unique(model.surface_triangles)
    front = surface[nodes[surface, 1] < np.median(nodes[surface, 1])]
    cloud = nodes[front] + np.array([2.0, -1.0, 0.5])
    once = physreg.register_partial_surface(physreg.PartialSurfaceCase(model, cloud), **SURFACE)
    twice = physreg.register_partial_surface(physreg.PartialSurfaceCase(model, np.vstack([cloud, cloud[::3]])), **SURFACE)
    repeats = len(cloud[::3])
    assert twice.summary["cloud"]["points"] == len(cloud)
    assert any(f"{repeats} cloud point(s) given more than once were left out" in n for n in twice.summary["notes"]), twice.summary["notes"]
    assert not any("more than once" in n for n in once.summary["notes"])
    assert np.abs(np.asarray(twice.displacement()) - np.asarray(once.displacement())).max() < 1e-9
