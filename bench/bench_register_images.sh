#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Run time of paper 002's biomechanical registration (physreg register-images, no baselines) on the
# phantom's insufflated organs (segmentation pair), for a model-size sweep (--cell-size), each run
# REPEAT times in this one session; the split (factorisations, solves, meshing) comes from the
# summary. Targets: one registration ≤ 60 s (issue 16, 28) and ≤ 30 s (issue 30) on 2 cores for a
# 50 k-tetrahedra model. Each size runs with the default solves (CG preconditioned by an earlier
# factor, issue 30) and with --no-factor-reuse (a factorisation per set of moduli), in one session.
# Kidneys left out as in the study (the phantom can lose one; docs/registration.md).
# Usage: bench/bench_register_images.sh [PHYSREG] [OUT.json] [REPEAT] [DATASET]
set -euo pipefail
physreg=${1:-build/bin/physreg}
out=${2:-bench/results/bench_register_images.json}
repeat=${3:-2}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
dataset=${4:-}
if [ -z "$dataset" ]; then
  dataset="$work/ph"
  "$physreg" --log-level warn phantom --materials healthy --seed 2 --organs-only --depths 5 --no-calculix --insufflation-pa 500 -o "$dataset"
fi
runs=()
for cell in 6 4 3; do
  for r in $(seq "$repeat"); do
    for variant in reuse direct; do
      dir="$work/run_${cell}_${variant}_$r"
      extra=(); [ "$variant" = direct ] && extra=(--no-factor-reuse)
      OMP_NUM_THREADS=2 "$physreg" --log-level warn register-images --dataset "$dataset" --state insufflation --structures 2,3,4 --baselines none \
        --cell-size "$cell" "${extra[@]}" -o "$dir" > /dev/null 2>&1
      runs+=("$dir/summary.json")
    done
  done
done
python3 - "$out" "${runs[@]}" <<'PY'
import json, statistics, sys, platform, os, datetime
out, files = sys.argv[1], sys.argv[2:]
groups = {}
for f in files:
    s = json.load(open(f))
    m = s["methods"]["biomechanical"]
    key = (s["model"]["tetrahedra"], m.get("factor_reuse", False))
    g = groups.setdefault(key, {"tetrahedra": key[0], "factor_reuse": key[1], "pcg_iterations": m.get("pcg_iterations", 0), "nodes": s["model"]["nodes"], "cell_size_mm": s["parameters"]["cell_size_mm"], "seconds": [],
                                "meshing_s": [], "cycles": m["cycles"], "evaluations": m["evaluations"], "factorisations": m["factorisations"],
                                "time_split_s": m["time_split_s"], "internal_tre_mm": m["tre"]["internal"]["mean_mm"], "rms_distance_mm": m["rms_distance_mm"]})
    g["seconds"].append(m["seconds"])
    g["meshing_s"].append(s["model"]["meshing_s"])
for g in groups.values():
    g["median_s"] = statistics.median(g["seconds"])
    g["median_with_meshing_s"] = statistics.median(a + b for a, b in zip(g["seconds"], g["meshing_s"]))
result = {"benchmark": "register-images --structures 2,3,4 --baselines none, phantom insufflation (healthy, seed 2, 500 Pa, organs only), OMP_NUM_THREADS=2",
          "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}, "date": datetime.datetime.now().isoformat(timespec="seconds"),
          "target": "≤ 60 s (issue 28) / ≤ 30 s (issue 30) for 50 k tetrahedra",
          "groups": sorted(groups.values(), key=lambda g: (g["tetrahedra"], g["factor_reuse"]))}
for g in result["groups"]:
    if g["factor_reuse"]:
        direct = [h for h in result["groups"] if h["tetrahedra"] == g["tetrahedra"] and not h["factor_reuse"]]
        if direct:
            g["speed_up_over_direct"] = direct[0]["median_s"] / g["median_s"]
json.dump(result, open(out, "w"), indent=1)
for g in result["groups"]:
    print(f'{g["tetrahedra"]:7d} tets  {"reuse " if g["factor_reuse"] else "direct"}  registration median {g["median_s"]:.1f} s (+ meshing {statistics.median(g["meshing_s"]):.1f} s)  '
          f'cycles {g["cycles"]} evaluations {g["evaluations"]} factorisations {g["factorisations"]}  internal TRE {g["internal_tre_mm"]:.2f} mm')
PY
