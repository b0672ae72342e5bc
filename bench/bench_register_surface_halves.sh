#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# What the cloud-halves check (issue 46 item 5) costs: register-surface with its defaults on the
# small preset's large push (seed 2, organs alone, a 15 mm sphere pressed 30 mm, the 500-point cloud
# over 90 % of the surface; 7 mm cells, about 9 k tetrahedra), whole pipeline (support hypotheses,
# rigid baselines, biomechanical method, evaluation) with --uncertainty halves (the default) and
# --uncertainty none, each REPEAT times in this one session, interleaved; the ratio of medians.
# Target (issue 46): 10 k tetrahedra ≤ 5 s with all hypotheses, speed unchanged within 1.5×.
# Usage: bench/bench_register_surface_halves.sh [PHYSREG] [OUT.json] [REPEAT] [EXISTING_DATASET]
set -euo pipefail
physreg=${1:-build/bin/physreg}
out=${2:-bench/results/bench_register_surface_halves.json}
repeat=${3:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
dataset=${4:-}
if [ -z "$dataset" ]; then
  dataset="$work/ph"
  "$physreg" --log-level warn phantom --preset small --materials healthy --seed 2 --organs-only --depths 5 --no-calculix --insufflation-pa 0 \
    --push-depth 30 --push-tool-radius 15 -o "$dataset"
fi
runs=()
for r in $(seq "$repeat"); do
  for mode in halves none; do
    dir="$work/run_${mode}_$r"
    OMP_NUM_THREADS=2 "$physreg" --log-level warn --no-report register-surface --dataset "$dataset" --state push --uncertainty "$mode" -o "$dir" > /dev/null 2>&1
    runs+=("$dir/summary.json")
  done
done
python3 - "$out" "${runs[@]}" <<'PY'
import json, statistics, sys, platform, os, datetime
out, files = sys.argv[1], sys.argv[2:]
groups = {}
for f in files:
    s = json.load(open(f))
    mode = s["settings"]["uncertainty"]
    g = groups.setdefault(mode, {"uncertainty": mode, "tetrahedra": s["model"]["tetrahedra"], "seconds": [], "halves_seconds": [],
                                 "answer": s["safeguard"]["answer"], "internal_tre_mm": s["methods"][s["safeguard"]["answer"]]["tre"]["internal"]["mean_mm"],
                                 "at_rest_internal_tre_mm": s["methods"]["at_rest"]["tre"]["internal"]["mean_mm"]})
    g["seconds"].append(s["seconds"])
    if s["uncertainty"].get("run"):
        g["halves_seconds"].append(s["uncertainty"]["seconds"])
        g["spread_mm"], g["motion_mm"], g["resolved"] = s["uncertainty"]["spread_mm"], s["uncertainty"]["motion_mm"], s["uncertainty"]["resolved"]
for g in groups.values():
    g["median_s"] = statistics.median(g["seconds"])
result = {"benchmark": "register-surface whole pipeline with and without the cloud-halves check (small push, 2 threads)",
          "date": datetime.datetime.now().isoformat(timespec="seconds"), "host": platform.node(), "cpus": os.cpu_count(),
          "runs": list(groups.values()),
          "ratio_halves_over_none": groups["halves"]["median_s"] / groups["none"]["median_s"]}
json.dump(result, open(out, "w"), indent=1)
print(json.dumps({k: v for k, v in result.items() if k != "runs"}, indent=1))
for g in groups.values():
    print(f"{g['uncertainty']}: median {g['median_s']:.2f} s over {len(g['seconds'])} runs ({g['tetrahedra']} tetrahedra), answer {g['answer']}, internal TRE {g['internal_tre_mm']:.2f} mm")
PY
