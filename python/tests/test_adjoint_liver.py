# SPDX-License-Identifier: GPL-3.0-or-later
"""Issue 56 on public data made elsewhere: the adjoint-liver of Mestdagh & Cotin (MICCAI 2022) in
../shared/data/adjoint-liver (GPL-3.0): a tetrahedral liver pushed by a tool, truth at every node,
a 500-point cloud over part of the pushed surface. The study (scripts/study_adjoint_liver.py) runs
45 frames beside the authors' code; these tests take one frame and skip without ../shared."""
from pathlib import Path

import numpy as np
import pytest

import physreg

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "adjoint-liver"
LIVER = DATA / "data" / "liver"
pytestmark = pytest.mark.skipif(not (LIVER / "mesh-default" / "liver.msh").exists(), reason="../shared/data/adjoint-liver is absent")


@pytest.fixture(scope="module")
def frame():
    """neohookean/s1 frame 0 in mm: the model (the generator's own mesh), the cloud, the truth at
    the 604 interior nodes, the generator's Dirichlet nodes and the sequence's force patch."""
    return load_frame(0)


def load_frame(k, sequence="s1"):
    mesh = physreg.read_mesh(LIVER / "mesh-default" / "liver.msh")
    mesh.nodes[:] *= 1000.0  # the package is in metres
    model = physreg.SurfaceModel.from_mesh(mesh)
    rest = np.array(mesh.nodes)
    seq = LIVER / "sequences" / "neohookean" / sequence
    truth = 1000.0 * np.load(seq / "positions-default.npy")[k]
    cloud = 1000.0 * np.loadtxt(seq / "pointclouds" / f"pc{k:02d}.txt")
    interior = np.setdiff1d(np.arange(len(rest)), np.unique(model.surface_triangles))
    assert len(interior) == 604
    landmarks = {f"n{i}": tuple(rest[i]) for i in interior}
    true = {f"n{i}": tuple(truth[i]) for i in interior}
    at_rest = float(np.linalg.norm(truth[interior] - rest[interior], axis=1).mean())
    return dict(model=model, cloud=cloud, landmarks=landmarks, truth=true, at_rest=at_rest,
                dirichlet=[int(i) for i in np.load(LIVER / "mesh-default" / "dirichlet-vertices.npy")],
                patch=[int(i) for i in np.load(seq / "forces-vertices-default.npy")])


def tre(result, method=None):
    return result.summary["methods"][method or result.method]["tre"]["all"]["mean_mm"]


def test_the_trap_a_turned_rest_shape_is_never_the_answer(frame):
    """With the mesh and the cloud alone (the defaults): the rigid fit turns the liver far (22°) and
    fits the 500 points better than the deformed model does, yet it is 5x farther from the truth than
    leaving the liver at rest. It must neither replace nor flag the answer, which must beat rest
    (measured 2026-12-05: 1.15 mm against 2.95 at rest; 1.25 mm since the springs are graded by the
    distance to the cloud, 2026-12-06; rigid 16.2 mm; the peer, told the supports and the force
    patch, 0.55 mm)."""
    case = physreg.PartialSurfaceCase(frame["model"], frame["cloud"], landmarks=frame["landmarks"], truth=frame["truth"])
    r = physreg.register_surface(case, uncertainty="none")  # the mode's one name: in memory, given a case
    assert isinstance(r, physreg.PartialSurfaceRegistration)
    s, guard = r.summary, r.summary["safeguard"]
    rigid, rest = s["methods"]["rigid"], s["methods"]["at_rest"]
    # The trap is there: a large pose that fits the cloud better than the answer and than rest…
    assert rigid["implied_rigid_motion"]["rotation_deg"] > 15.0, rigid["implied_rigid_motion"]
    assert rigid["cloud_to_model_mm"]["mean"] < rest["cloud_to_model_mm"]["mean"]
    assert tre(r, "rigid") > 2.0 * frame["at_rest"]
    # …and it is set aside, with the reason said.
    assert r.method == "adjoint" and guard["answer"] == "adjoint" and guard["flags"] == [], guard
    assert any("turns the model by" in n and "trap of a local push" in n for n in guard["notes"]), guard["notes"]
    assert guard["runner_up"] != "rigid"
    assert tre(r) <= 0.6 * frame["at_rest"], (tre(r), frame["at_rest"])


def test_told_the_supports_and_where_the_tool_pressed_beats_the_peer(frame):
    """The peer's information (the 106 Dirichlet nodes held, forces on the 60-node patch): the
    adjoint method's controls act on the patch alone, and it beats the peer's own published 0.55 mm
    on this frame (measured 2026-12-05: 0.37 mm)."""
    case = physreg.PartialSurfaceCase(frame["model"], frame["cloud"], landmarks=frame["landmarks"], truth=frame["truth"],
                                      support_nodes=frame["dirichlet"], load_nodes=frame["patch"])
    r = physreg.register_partial_surface(case, uncertainty="none")
    s = r.summary
    assert s["support"] == "named" and s["load_region"]["held_by_supports"] == 0, s["load_region"]
    assert sorted(s["load_region"]["nodes"]) == sorted(set(frame["patch"]))
    assert r.method == "adjoint" and tre(r) <= 0.55, tre(r)


def test_told_the_supports_alone_a_nearly_incompressible_model_stays_within_a_quarter_of_the_peer():
    """Issue 56's target "no frame over 1.25x the peer" with the Dirichlet nodes alone (no force
    patch). neohookean/s2 frame 40 was the frame that missed it: the peer, told the supports and
    the force patch, reaches 0.78 mm there (peer/run_peer.py, scripts/study_adjoint_liver.py,
    2026-12-06); physreg with ν 0.45 (paper 001's value, the default until then) 1.25 mm. The default
    ν 0.48 (tissue nearly incompressible; the generator's is 0.49, its law Neo-Hookean, ours
    co-rotational) comes within 1.25x; ν 0.45 does not."""
    f = load_frame(40, "s2")
    peer_mm = 0.78
    case = physreg.PartialSurfaceCase(f["model"], f["cloud"], landmarks=f["landmarks"], truth=f["truth"], support_nodes=f["dirichlet"])
    default = physreg.register_partial_surface(case, uncertainty="none")
    assert default.summary["model"]["poisson_ratio"] == 0.48
    assert default.method == "adjoint" and tre(default) <= 1.25 * peer_mm, (tre(default), f["at_rest"])
    old = physreg.register_partial_surface(case, uncertainty="none", poisson=0.45)
    assert tre(old) > 1.25 * peer_mm > tre(default), (tre(old), tre(default))


def test_a_load_region_nowhere_near_the_cloud_is_refused(frame):
    """Bad input: a force region the tool cannot have pressed (the surface nodes farthest from the
    cloud) is a clear error naming the distance, before any work."""
    model = frame["model"]
    nodes = np.array(model.mesh.nodes)
    surface = np.unique(model.surface_triangles)
    far = surface[np.argsort([np.min(np.linalg.norm(frame["cloud"] - nodes[i], axis=1)) for i in surface])[-5:]]
    case = physreg.PartialSurfaceCase(model, frame["cloud"], load_nodes=[int(i) for i in far])
    with pytest.raises(physreg.Error, match=r"the load region .* lies [0-9.]+ mm from the nearest cloud point, farther than --max-pair-distance 40 mm"):
        physreg.register_partial_surface(case)
    inside = np.setdiff1d(np.arange(len(nodes)), surface)[:1]
    with pytest.raises(physreg.Error, match="is not on the model's surface"):
        physreg.register_partial_surface(physreg.PartialSurfaceCase(model, frame["cloud"], load_nodes=[int(inside[0])]))


def test_the_predicted_error_ranks_a_small_and_a_large_push(frame):
    """Issue 56 item 6: the error predicted from the answer's strain energy, on two frames the
    calibration never saw (it used frames 0, 10, .., 40): the larger push is predicted the larger
    error, as it is, and the stated interval is a real interval around the prediction."""
    small, large = load_frame(5), load_frame(45)
    out = []
    for f in (small, large):
        case = physreg.PartialSurfaceCase(f["model"], f["cloud"], landmarks=f["landmarks"], truth=f["truth"])
        p = physreg.register_partial_surface(case, uncertainty="none")
        out.append((p.summary["predicted_error"], tre(p, "adjoint")))
    (p5, t5), (p45, t45) = out
    assert t45 > t5 and p45["mean_mm"] > p5["mean_mm"], (p5, t5, p45, t45)
    for p, _ in out:
        assert p["regime"] == "springs" and p["interval_mm"][0] < p["mean_mm"] < p["interval_mm"][1]
        assert "strain energy" in p["statement"]
