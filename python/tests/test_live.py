# SPDX-License-Identifier: GPL-3.0-or-later
"""The live layer from Python (issue 59 item 6): physreg.serve runs the library's session in this
process, physreg.LiveClient is a tracker's side of it. A pose moves the targets where
register-compression --solver condensed puts them for the same final pose, as through the command
(test_serve.py); bad options are refused before anything is prepared; Ctrl-C-like stops end it."""
import socket
import threading
import time

import numpy as np
import pytest

import physreg
from test_serve import GRID, final_pose_lps


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def connect(port, timeout_s=120.0):
    """The server prepares the model first: connect once it listens."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return physreg.LiveClient(f"127.0.0.1:{port}")
        except physreg.Error:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def test_a_pose_sent_by_the_client_moves_the_targets_as_the_command_does(dataset):
    port = free_port()
    failure = []

    def run():
        try:
            physreg.serve(dataset=dataset, port=port, once=True, grid=GRID)
        except Exception as e:  # noqa: BLE001 - reported to the test thread below
            failure.append(e)

    server = threading.Thread(target=run)
    server.start()
    client = connect(port)
    stamp = client.send_pose(final_pose_lps(dataset, "A"))
    assert stamp == 1 << 32  # the first pose, in whole seconds
    seen = {}
    while "targets" not in seen:
        m = client.read(timeout_s=60.0)
        assert m is not None, "no answer within 60 s"
        assert m["timestamp"] == stamp, m
        seen[m["device"]] = m
    del client  # the only client leaves: the session (once) ends
    server.join(timeout=60)
    assert not server.is_alive() and not failure, failure
    liver = seen["liver"]
    assert liver["type"] == "POLYDATA" and liver["points"].shape[0] > 100 and np.isfinite(liver["points"]).all()
    targets = seen["targets"]
    assert targets["type"] == "POINT" and len(targets["names"]) == 25
    served = dict(zip(targets["names"], targets["points"]))
    subject = physreg.CompressionSubject.from_dataset(dataset, grid=GRID)
    r = physreg.predict_compression(subject, physreg.CompressionCase.from_dataset(dataset, "A"), solver="condensed")
    worst = max(np.linalg.norm(served[n] - np.array(p)) for n, p in r.landmarks.items())
    moved = max(np.linalg.norm(np.array(p) - np.array(subject.rest_landmarks[n])) for n, p in r.landmarks.items())
    assert moved > 0.5 and worst < 0.01, (worst, moved)  # mm (float32 on the wire), LPS back from RAS


def test_impossible_options_are_refused_before_any_work(dataset, tmp_path):
    with pytest.raises(physreg.Error, match=r"give a prepared MODEL .* or --dataset DIR, not both"):
        physreg.serve(model=tmp_path, dataset=dataset, port=free_port())
    with pytest.raises(physreg.Error, match=r"--port 70000 must lie in 1"):
        physreg.serve(dataset=dataset, port=70000)
    with pytest.raises(physreg.Error, match=r"--frame 'xyz'"):
        physreg.serve(dataset=dataset, port=free_port(), frame="xyz")
    with pytest.raises(physreg.Error, match=r"live client"):
        physreg.LiveClient(f"127.0.0.1:{free_port()}")  # nobody listens there
    with pytest.raises(physreg.Error, match=r"frame 'xyz'"):
        physreg.LiveClient("127.0.0.1:1", frame="xyz")
