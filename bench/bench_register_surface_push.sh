#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Run time of issue 32's two methods on the large local push (cirs057a, healthy, seed 2, organs
# alone, a 25 mm sphere pressed 40 mm, a 500-point cloud over 90 % of the surface; 7 mm cells,
# ≈ 10.9 k tetrahedra): the default biomechanical registration (posterior held) and --method
# adjoint, each REPEAT times in this one session, with their ratio and accuracy.
# Targets (issue 32): ≤ 5 s default, ≤ 30 s adjoint, per registration of 10 k tetrahedra.
# Usage: bench/bench_register_surface_push.sh [PHYSREG] [OUT.json] [REPEAT] [EXISTING_DATASET]
set -euo pipefail
physreg=${1:-build/bin/physreg}
out=${2:-bench/results/bench_register_surface_push.json}
repeat=${3:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
dataset=${4:-}
if [ -z "$dataset" ]; then
  dataset="$work/ph"
  "$physreg" --log-level warn phantom --materials healthy --seed 2 --organs-only --depths 5 --no-calculix --insufflation-pa 0 \
    --push-depth 40 --push-tool-radius 12.5 -o "$dataset"
fi
runs=()
for method in biomechanical adjoint; do
  for r in $(seq "$repeat"); do
    dir="$work/run_${method}_$r"
    OMP_NUM_THREADS=2 "$physreg" --log-level warn --no-report register-surface --dataset "$dataset" --state push --method "$method" -o "$dir" > /dev/null 2>&1
    runs+=("$dir/summary.json")
  done
done
python3 - "$out" "${runs[@]}" <<'PY'
import json, statistics, sys, platform, os, datetime
out, files = sys.argv[1], sys.argv[2:]
groups = {}
for f in files:
    s = json.load(open(f))
    name = s["method"]
    m = s["methods"][name]
    g = groups.setdefault(name, {"method": name, "tetrahedra": s["model"]["tetrahedra"], "seconds": [], "internal_tre_mm": m["tre"]["internal"]["mean_mm"],
                                 "at_rest_internal_tre_mm": s["methods"]["at_rest"]["tre"]["internal"]["mean_mm"], "cloud_points": s["cloud"]["points"]})
    g["seconds"].append(m["seconds"])
for g in groups.values():
    g["median_s"] = statistics.median(g["seconds"])
result = {"benchmark": "register-surface on the large local push (cirs057a healthy seed 2, 40 mm by a 25 mm sphere, 500-point cloud)",
          "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}, "date": datetime.datetime.now().isoformat(timespec="seconds"),
          "targets_s": {"biomechanical": 5.0, "adjoint": 30.0}, "groups": list(groups.values()),
          "adjoint_over_biomechanical": groups["adjoint"]["median_s"] / groups["biomechanical"]["median_s"]}
json.dump(result, open(out, "w"), indent=1)
for g in groups.values():
    print(f'{g["method"]:14s} {g["tetrahedra"]} tets median {g["median_s"]:.2f} s ({", ".join(f"{x:.2f}" for x in g["seconds"])}), internal TRE {g["internal_tre_mm"]:.2f} mm (at rest {g["at_rest_internal_tre_mm"]:.2f})')
print(f'adjoint / biomechanical: {result["adjoint_over_biomechanical"]:.2f}')
PY
