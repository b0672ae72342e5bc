#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# The enrichment database against its size (issue 31 item 3). On a demo's output (its phantom and
# fitted parameters), builds databases from the training positions (A, B, C) and from grids of tool
# positions over the skin (never D's or E's own poses), then predicts the held-out D and E
# coarse-to-fine with each: the stored detail at any distance (paper 000, --detail-length inf) and
# with the detail length chosen by leave-one-position-out (auto). Also times the build of one grid on
# 1 and 2 threads and on 2 MPI ranks. Not run by CI (the quick demo's grids take ≈ 10 min on 2 cores).
#   scripts/study_database.sh DEMO_OUT OUT [GRIDS]     (default GRIDS "3x2 6x4 9x6")
# DEMO_OUT: `physreg demo [--quick] -o DEMO_OUT`. Settings read from DEMO_OUT/summary.json (grids,
# depths); TIMING_GRID (default the middle grid) is the one timed on threads and ranks.
set -euo pipefail
demo=${1:?usage: study_database.sh DEMO_OUT OUT [GRIDS]}
out=${2:?usage: study_database.sh DEMO_OUT OUT [GRIDS]}
read -r -a grids <<< "${3:-3x2 6x4 9x6}"
timing_grid=${TIMING_GRID:-${grids[$(( ${#grids[@]} / 2 ))]}}
physreg=${PHYSREG:-build/bin/physreg}
mkdir -p "$out"
read -r coarse depths < <(python3 - "$demo" <<'PY'
import json, sys
s = json.load(open(f"{sys.argv[1]}/summary.json"))
quick = s["preset"] == "small"
print("20x15x10" if quick else "27x20x13", "4,8,12,15" if quick else "5,10,15,20,25")
PY
)
common=(--dataset "$demo/phantom" --parameters "$demo/params.json" --coarse-grid "$coarse" --depths "$depths")
root=()
[ "$(id -u)" -eq 0 ] && root=(--allow-run-as-root)

build() { # NAME THREADS RANKS ARGS...
  local name=$1 threads=$2 ranks=$3
  shift 3
  local start
  start=$(date +%s.%N)
  if [ "$ranks" -gt 1 ]; then
    OMP_NUM_THREADS=$threads mpirun "${root[@]}" --oversubscribe -np "$ranks" "$physreg" -q enrich build "${common[@]}" "$@" \
      -o "$out/$name.phe" --force --json > "$out/$name.build.json"
  else
    OMP_NUM_THREADS=$threads "$physreg" -q enrich build "${common[@]}" "$@" -o "$out/$name.phe" --force --json > "$out/$name.build.json"
  fi
  echo "{\"wall_s\": $(echo "$(date +%s.%N) - $start" | bc), \"threads\": $threads, \"ranks\": $ranks}" > "$out/$name.time.json"
}

apply() { # NAME
  local name=$1
  for state in D E; do
    for detail in inf auto; do
      "$physreg" -q --no-report enrich apply --database "$out/$name.phe" --dataset "$demo/phantom" --parameters "$demo/params.json" --state "$state" \
        --detail-length "$detail" -o "$out/$name-$state-$detail" --force --json > "$out/$name-$state-$detail.json"
    done
  done
}

build training 2 1 --positions A,B,C
apply training
for g in "${grids[@]}"; do
  build "grid$g" 2 1 --positions-grid "$g"
  apply "grid$g"
done
build "grid$timing_grid-1thread" 1 1 --positions-grid "$timing_grid"
build "grid$timing_grid-2ranks" 1 2 --positions-grid "$timing_grid"
cmp "$out/grid$timing_grid.phe" "$out/grid$timing_grid-2ranks.phe"

python3 - "$out" "$timing_grid" "${grids[@]}" <<'PY'
import json, pathlib, sys
out, timing = pathlib.Path(sys.argv[1]), sys.argv[2]
names = ["training"] + [f"grid{g}" for g in sys.argv[3:]]
rows = []
for name in names:
    b = json.loads((out / f"{name}.build.json").read_text())
    t = json.loads((out / f"{name}.time.json").read_text())
    row = {"database": name, "conditions": b["conditions"], "megabytes": round(b["file_bytes"] / 1e6, 1), "build_s": round(t["wall_s"], 1)}
    for detail in ("inf", "auto"):
        tre, inside, near, share, length = [], [], [], [], None
        for state in "DE":
            s = json.loads((out / f"{name}-{state}-{detail}.json").read_text())
            tre.append(s["tre_against_dataset"]["all"]["mean_mm"])
            inside.append(not s["outside_range"])
            near.append(s["nearest_stored_position_mm"])
            share.append(s["detail_share"])
            length = s["detail_length_mm"]
        row[f"held_out_tre_mm_detail_{detail}"] = round(sum(tre) / 2, 3)
        if detail == "auto":
            row["detail_length_mm"] = length
            row["detail_share_D_E"] = [round(x, 3) for x in share]
        row["inside_range_D_E"] = inside
        row["nearest_position_mm_D_E"] = [round(x, 1) for x in near]
    rows.append(row)
timings = {}
for suffix, label in (("", "2 threads"), ("-1thread", "1 thread"), ("-2ranks", "2 MPI ranks x 1 thread")):
    t = json.loads((out / f"grid{timing}{suffix}.time.json").read_text())
    timings[label] = round(t["wall_s"], 1)
result = {"rows": rows, "build_time_s_grid_" + timing: timings,
          "note": "held-out TRE: mean over D and E of the landmarks' mean TRE, one-shot coarse-to-fine (enrich apply)"}
(out / "study_database.json").write_text(json.dumps(result, indent=2) + "\n")
print("| database | conditions | MB | build s | nearest position D, E (mm) | inside D, E | TRE detail ∞ (mm) | TRE detail auto (mm) | length (mm) |")
print("|---|---|---|---|---|---|---|---|---|")
for r in rows:
    print(f"| {r['database']} | {r['conditions']} | {r['megabytes']} | {r['build_s']} | {r['nearest_position_mm_D_E']} | {r['inside_range_D_E']} | "
          f"{r['held_out_tre_mm_detail_inf']} | {r['held_out_tre_mm_detail_auto']} | {r['detail_length_mm']} |")
print(f"build of grid {timing}: " + ", ".join(f"{k} {v} s" for k, v in timings.items()))
PY
