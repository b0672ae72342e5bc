#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 56's time target: one `register-surface` of the public 3 046-node liver (adjoint-liver,
# neohookean/s1 frame 0, the 500-point cloud, 604 interior targets) with its defaults — support
# hypotheses, rigid baselines from several starts, the cloud-halves check, the adjoint answer, the
# safeguard — against ≤ 10 s. Runs the default and `--method biomechanical` interleaved, REPEAT
# times each in one session; writes where the time went (the summary's per-method seconds).
# Usage: /usr/bin/python3 bench/bench_register_surface_liver.py [--physreg build/bin/physreg]
#            [--out bench/results/bench_register_surface_liver.json] [--repeat 3] [--compare OTHER_PHYSREG]
# --compare adds a third variant, the defaults with another build (its lib/ found from its bin/ by
# RUNPATH or LD_LIBRARY_PATH as given), interleaved with the others: the ratio comes from one run.
# Needs ../shared/data/adjoint-liver and numpy.
import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import numpy as np  # noqa: E402
import study_adjoint_liver as study  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
ap.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "bench_register_surface_liver.json"))
ap.add_argument("--repeat", type=int, default=3)
ap.add_argument("--compare", help="another physreg binary whose defaults run interleaved with this one's")
a = ap.parse_args()
if not os.path.isdir(study.DATA):
    sys.exit(f"{study.DATA} is missing")
work = tempfile.mkdtemp()
nodes, interior, names, common = study.prepare(work)
seq = os.path.join(study.DATA, "data", "liver", "sequences", "neohookean", "s1")
cloud = 1000.0 * np.loadtxt(os.path.join(seq, "pointclouds", "pc00.txt"))
with open(os.path.join(work, "cloud.csv"), "w") as f:
    f.write("x,y,z\n" + "".join("%.6f,%.6f,%.6f\n" % tuple(p) for p in cloud))
truth = 1000.0 * np.load(os.path.join(seq, "positions-default.npy"))[0]
study.write_points(os.path.join(work, "true.csv"), names, truth[interior])
runs = {"default": [], "biomechanical": []}
if a.compare:
    runs["default_compared"] = []
for r in range(a.repeat):
    for variant in runs:
        out = os.path.join(work, f"{variant}_{r}")
        cmd = [a.compare if variant == "default_compared" else a.physreg, "-q", "--no-report", "register-surface", "--model", os.path.join(common, "liver_mm.msh"), "--cloud",
               os.path.join(work, "cloud.csv"), "--landmarks", os.path.join(common, "targets_rest.csv"), "--landmarks-truth",
               os.path.join(work, "true.csv"), "-o", out]
        if variant == "biomechanical":
            cmd += ["--method", "biomechanical"]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="2"))
        s = json.load(open(os.path.join(out, "summary.json")))
        # A method reported "same_as" another (plain ICP on an unlabelled cloud) was not run again.
        split = {m: 0.0 if "same_as" in v else v.get("seconds", 0.0) for m, v in s["methods"].items()}
        split["halves"] = s["uncertainty"].get("seconds", 0.0)
        split["support_hypotheses"] = sum(h["seconds"] for h in s["support_hypotheses"]["hypotheses"])
        runs[variant].append({"seconds": s["seconds"], "split_s": split, "answer": s["safeguard"]["answer"],
                              "tre_mm": s["methods"][s["safeguard"]["answer"]]["tre"]["all"]["mean_mm"]})
result = {"benchmark": "register-surface defaults on the adjoint-liver (3 046 nodes, 10 703 tetrahedra, 500 points), 2 threads",
          "date": datetime.datetime.now().isoformat(timespec="seconds"), "host": platform.node(), "cpus": os.cpu_count(),
          "target_s": 10.0, "runs": runs,
          "median_s": {v: statistics.median(r["seconds"] for r in runs[v]) for v in runs}}
if a.compare:
    result["compared_binary"] = a.compare
    result["ratio_default_to_compared"] = result["median_s"]["default"] / result["median_s"]["default_compared"]
os.makedirs(os.path.dirname(a.out), exist_ok=True)
json.dump(result, open(a.out, "w"), indent=1)
for v, rs in runs.items():
    print(f"{v}: median {result['median_s'][v]:.1f} s over {len(rs)} runs (answer {rs[0]['answer']}, TRE {rs[0]['tre_mm']:.2f} mm); "
          f"split of the first: " + ", ".join(f"{k} {t:.1f}" for k, t in rs[0]["split_s"].items()))
if a.compare:
    print(f"default against {a.compare}: {result['ratio_default_to_compared']:.2f}× its median time")
