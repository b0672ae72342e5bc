# SPDX-License-Identifier: GPL-3.0-or-later
"""OpenBLAS's kernels: a Python process on a CPU OpenBLAS does not know is told which kernels to ask
for (the physreg program asks for them itself; tests/cli/test_cli.sh checks that)."""
import os
import subprocess
import sys

import pytest

import physreg

PROBE = (
    "import warnings\n"
    "with warnings.catch_warnings(record=True) as caught:\n"
    "    warnings.simplefilter('always')\n"
    "    import physreg\n"
    "print(physreg.openblas_kernels())\n"
    "print(physreg.openblas_better_kernels())\n"
    "print(' | '.join(str(w.message) for w in caught if 'OPENBLAS_CORETYPE' in str(w.message)))\n"
)


def probe(**env):
    environment = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    environment.update(env)
    r = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=environment, check=True)
    kernels, better, warning = (r.stdout.splitlines() + ["", "", ""])[:3]
    return kernels, better, warning


def cpu_flags():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def test_the_hint_names_kernels_this_cpu_runs_exactly_when_openblas_fell_back():
    if not physreg.openblas_kernels():
        pytest.skip("the BLAS linked in is not OpenBLAS")
    kernels, better, warning = probe()
    flags = cpu_flags()
    if kernels.lower() != "prescott":
        assert better == "" and warning == "", (kernels, better, warning)
        return
    # The generic kernels: a hint exactly when the CPU runs better ones, and it names them.
    expected = ""
    if {"avx512f", "avx512bw", "avx512dq", "avx512vl"} <= flags:
        expected = "SkylakeX"
    elif {"avx2", "fma"} <= flags:
        expected = "Haswell"
    assert better == expected
    if expected:
        assert f"OPENBLAS_CORETYPE={expected}" in warning
        # Started as the hint says, OpenBLAS takes those kernels and the hint is gone.
        kernels2, better2, warning2 = probe(OPENBLAS_CORETYPE=expected)
        assert kernels2 == expected and better2 == "" and warning2 == "", (kernels2, better2, warning2)
    else:
        assert warning == ""


def test_kernels_the_user_chose_are_kept_without_a_hint():
    if not physreg.openblas_kernels():
        pytest.skip("the BLAS linked in is not OpenBLAS")
    kernels, better, warning = probe(OPENBLAS_CORETYPE="Prescott")
    assert kernels == "Prescott"
    # Still the generic kernels, so the hint stands unless the CPU runs nothing better; a user's
    # choice is not overridden (the program keeps it too).
    assert (better == "") == (warning == "")
