# SPDX-License-Identifier: GPL-3.0-or-later
"""Shared fixtures: a small phantom dataset made once per session (physreg phantom --preset small)."""
import os
import shutil
import subprocess

import pytest

import physreg


@pytest.fixture(scope="session")
def dataset(tmp_path_factory):
    """A small phantom: one compression A (6 mm), insufflation; no CalculiX check (speed)."""
    out = tmp_path_factory.mktemp("phantom") / "ph"
    physreg.phantom(out, preset="small", seed=3, depths="6", no_calculix=True, quiet=True)
    return out


@pytest.fixture(scope="session")
def program():
    """The physreg program of the same build (to compare messages), or None."""
    path = os.environ.get("PHYSREG_EXECUTABLE") or shutil.which("physreg")
    return path


def skip_or_fail(reason):
    """Skips for want of a fixture, or fails in CI (CI=true), where every fixture must be there."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"a fixture is missing in CI (a skip there is a failure): {reason}")
    pytest.skip(reason)


def program_error(program, *args):
    """Runs the program, expects exit 1, returns the message after 'physreg: error: '."""
    r = subprocess.run([program, *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    line = [l for l in r.stderr.splitlines() if l.startswith("physreg: error: ")][-1]
    return line[len("physreg: error: "):]
