#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Run time of paper 001's registration (physreg register-surface) on the phantom's insufflated
# liver, 30 % of the surface visible: homogeneous vs heterogeneous (capsule + vessel beams),
# free-floating and with the posterior surface held, each run REPEAT times in this one session
# (the ratio is measured here, same machine, same hour). Also the model-size sweep (cell sizes).
# Usage: bench/bench_register_surface.sh [PHYSREG] [OUT.json] [REPEAT]
set -euo pipefail
physreg=${1:-build/bin/physreg}
out=${2:-bench/results/bench_register_surface.json}
repeat=${3:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$physreg" --log-level warn phantom --materials healthy --seed 1 --organs-only --depths 5 --no-calculix --insufflation-pa 175 -o "$work/ph"
runs=()
for cell in 7 10 5; do
  for kind in homogeneous heterogeneous; do
    for support in none posterior; do
      [ "$cell" != 7 ] && [ "$support" = posterior ] && continue
      for r in $(seq "$repeat"); do
        dir="$work/run_${cell}_${kind}_${support}_$r"
        OMP_NUM_THREADS=2 "$physreg" --log-level warn register-surface --dataset "$work/ph" --visible 30 --cell-size "$cell" \
          --model-kind "$kind" --support "$support" -o "$dir" > /dev/null 2>&1
        runs+=("$dir/summary.json")
      done
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
    key = f'{s["model"]["tetrahedra"]}tets/{s["model"]["kind"]}/{s["support"]}'
    g = groups.setdefault(key, {"tetrahedra": s["model"]["tetrahedra"], "kind": s["model"]["kind"], "support": s["support"], "seconds": [],
                                "time_steps": m["time_steps"], "internal_tre_mm": m["tre"]["internal"]["mean_mm"]})
    g["seconds"].append(m["seconds"])
for g in groups.values():
    g["median_s"] = statistics.median(g["seconds"])
ratios = {}
for support in ("none", "posterior"):
    hom = [g for g in groups.values() if g["kind"] == "homogeneous" and g["support"] == support]
    het = [g for g in groups.values() if g["kind"] == "heterogeneous" and g["support"] == support]
    for a in hom:
        for b in het:
            if a["tetrahedra"] == b["tetrahedra"]:
                ratios[f'{a["tetrahedra"]}tets/{support}'] = b["median_s"] / a["median_s"]
result = {"benchmark": "register-surface, phantom insufflation (healthy, seed 1, 175 Pa), 30 % visible",
          "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}, "date": datetime.datetime.now().isoformat(timespec="seconds"),
          "groups": list(groups.values()), "heterogeneous_over_homogeneous": ratios}
json.dump(result, open(out, "w"), indent=1)
for g in sorted(groups.values(), key=lambda g: (g["tetrahedra"], g["kind"], g["support"])):
    print(f'{g["tetrahedra"]:6d} tets {g["kind"]:14s} support={g["support"]:9s} median {g["median_s"]:.2f} s  ({", ".join(f"{x:.2f}" for x in g["seconds"])})  steps {g["time_steps"]}')
print("heterogeneous / homogeneous:", {k: round(v, 2) for k, v in ratios.items()})
PY
