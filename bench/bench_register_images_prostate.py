#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 57's time target: one `register-images` of a public MR → TRUS prostate gland pair
# (../shared/data/mrus-prostate-pairs, label maps only, landmarks for the TRE) with its defaults and
# the label baselines (rigid, Demons, B-spline on labels), against ≤ 30 s per pair. Every pair of the
# set once (or --pairs), in one session, 2 threads; writes the wall time per pair and where it went
# (the summary's per-method seconds).
# Usage: /usr/bin/python3 bench/bench_register_images_prostate.py [--physreg build/bin/physreg]
#            [--out bench/results/bench_register_images_prostate.json] [--pairs mrus_obs000,...]
import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = os.path.join(os.path.dirname(ROOT), "shared", "data", "mrus-prostate-pairs", "cases")

ap = argparse.ArgumentParser()
ap.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
ap.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "bench_register_images_prostate.json"))
ap.add_argument("--pairs", default="")
a = ap.parse_args()
if not os.path.isdir(CASES):
    sys.exit(f"{CASES} is missing")
pairs = sorted(os.listdir(CASES))
if a.pairs:
    pairs = [p for p in pairs if p in a.pairs.split(",")]
work = tempfile.mkdtemp()
runs = {}
for p in pairs:
    d = os.path.join(CASES, p)
    out = os.path.join(work, p)
    cmd = [a.physreg, "-q", "--no-report", "register-images", "--fixed-labels", os.path.join(d, "target_labels.nii.gz"),
           "--moving-labels", os.path.join(d, "source_labels.nii.gz"), "--landmarks-fixed", os.path.join(d, "target_landmarks.csv"),
           "--landmarks-moving", os.path.join(d, "source_landmarks.csv"), "--baselines", "labels", "-o", out]
    started = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="2"))
    wall = time.perf_counter() - started
    s = json.load(open(os.path.join(out, "summary.json")))
    runs[p] = {"wall_s": wall, "summary_seconds": s["seconds"],
               "split_s": {m: v.get("seconds", 0.0) for m, v in s["methods"].items()},
               "meshing_s": s["model"].get("meshing_s"), "nodes": s["model"]["nodes"]}
walls = [r["wall_s"] for r in runs.values()]
result = {"benchmark": "register-images defaults + label baselines on the 20 public MR-TRUS gland pairs (1.5 mm voxels), 2 threads",
          "date": datetime.datetime.now().isoformat(timespec="seconds"), "host": platform.node(), "cpus": os.cpu_count(),
          "target_s": 30.0, "runs": runs, "median_s": statistics.median(walls), "max_s": max(walls)}
os.makedirs(os.path.dirname(a.out), exist_ok=True)
json.dump(result, open(a.out, "w"), indent=1)
print(f"{len(runs)} pairs: median {result['median_s']:.1f} s, max {result['max_s']:.1f} s per pair (target 30 s)")
