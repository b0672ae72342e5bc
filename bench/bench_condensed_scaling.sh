#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Scaling of condensed contact (issue 30): `physreg bench condensed` on the body model of one
# dataset at grids from ≈ 10 k to ≈ 1 M hexahedra, one tool path (the first compression), 20 tool
# updates. Per grid: precomputation (assembly, CHOLMOD factorisation, candidate compliance), nnz(L),
# the memory estimate the limit is checked against, the process's peak RSS and the time per update.
# Then a table and the log-log slopes (least squares) against the number of hexahedra.
#   bench/bench_condensed_scaling.sh PHYSREG DATASET OUTDIR [GRID ...]
# DATASET: a body phantom (physreg phantom; e.g. `--depths 15 --insufflation-pa 0 --no-calculix`).
# Writes OUTDIR/grid_GRID.json (bench condensed's report, with wall time and peak RSS added) and
# OUTDIR/summary.json.
set -euo pipefail
physreg="$(readlink -f "$1")"
dataset="$2"
out="$3"
shift 3
grids=("$@")
[ ${#grids[@]} -gt 0 ] || grids=(32x24x15 46x34x22 69x51x32 100x73x47 148x110x70)
mkdir -p "$out"
state=$(python3 -c "import json,sys; m=json.load(open(sys.argv[1]+'/manifest.json')); print(next(s['name'] for s in m['states'] if s['kind']=='compression'))" "$dataset")
for g in "${grids[@]}"; do
  json="$out/grid_$g.json"
  rm -f "$json"
  echo "=== grid $g (state $state)"
  start=$(date +%s.%N)
  if ! /usr/bin/time -f "%M" -o "$out/rss_$g.txt" "$physreg" --log-level warn bench condensed --dataset "$dataset" --grid "$g" \
       --states "$state" --held-out "$state" --steps 20 -o "$json" 2> "$out/log_$g.txt"; then
    tail -3 "$out/log_$g.txt"
    # Over the memory limit (or another error): kept as a row with the message.
    python3 -c "import json,sys; json.dump({'grid': sys.argv[1], 'error': open(sys.argv[2]).read().strip().splitlines()[-1]}, open(sys.argv[3], 'w'))" \
      "$g" "$out/log_$g.txt" "$json"
    continue
  fi
  end=$(date +%s.%N)
  python3 - "$json" "$g" "$start" "$end" "$out/rss_$g.txt" <<'PY'
import json, sys
path, grid, start, end, rss = sys.argv[1:]
r = json.load(open(path))
r["grid"] = grid
r["wall_s"] = float(end) - float(start)
r["max_rss_mb"] = int(open(rss).read().split()[-1]) * 1024 / 1e6
json.dump(r, open(path, "w"), indent=2)
PY
  tail -1 "$out/log_$g.txt"
done
python3 - "$out" "${grids[@]}" <<'PY'
import json, math, sys
out, grids = sys.argv[1], sys.argv[2:]
rows, errors = [], []
for g in grids:
    r = json.load(open(f"{out}/grid_{g}.json"))
    if "error" in r:
        errors.append(r)
        continue
    p = r["precomputation"]
    rows.append({
        "grid": g, "hexahedra": r["model"]["hexahedra"], "nodes": r["model"]["nodes"], "dofs": p["dofs"],
        "factor_nonzeros": p["factor_nonzeros"], "candidate_nodes": p["candidate_nodes"], "query_nodes": p["query_nodes"],
        "assembly_s": p["assembly_s"], "factorisation_s": p["factorisation_s"], "compliance_s": p["compliance_s"],
        "precomputation_s": p["assembly_s"] + p["factorisation_s"] + p["compliance_s"],
        "memory_estimate_mb": p["memory_estimate_mb"], "peak_rss_mb": r["max_rss_mb"], "wall_s": r["wall_s"],
        "ms_per_update": r["summary"]["ms_per_update"], "contact_ms": r["summary"]["contact_ms"], "recovery_ms": r["summary"]["recovery_ms"],
        "region_extensions": p["region_extensions"]["updates"],
    })

def slope(key):
    pts = [(math.log(x["hexahedra"]), math.log(x[key])) for x in rows if x[key] > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sum((p[0] - mx) ** 2 for p in pts)

keys = ["factorisation_s", "compliance_s", "precomputation_s", "factor_nonzeros", "memory_estimate_mb", "peak_rss_mb", "candidate_nodes",
        "ms_per_update"]
summary = {"what": "condensed contact against model size (bench/bench_condensed_scaling.sh)", "rows": rows, "errors": errors,
           "slopes_vs_hexahedra": {k: slope(k) for k in keys}}
json.dump(summary, open(f"{out}/summary.json", "w"), indent=2)
print("| hexahedra | dofs | nnz(L) | candidates | factor s | compliance s | precomputation s | memory est. MB | peak RSS MB | ms/update |")
print("|---|---|---|---|---|---|---|---|---|---|")
for x in rows:
    print(f"| {x['hexahedra']:,} | {x['dofs']:,} | {x['factor_nonzeros']:.3g} | {x['candidate_nodes']} | {x['factorisation_s']:.1f} | "
          f"{x['compliance_s']:.1f} | {x['precomputation_s']:.1f} | {x['memory_estimate_mb']:.0f} | {x['peak_rss_mb']:.0f} | {x['ms_per_update']:.3f} |")
for e in errors:
    print(f"| grid {e['grid']}: {e['error']} |")
print("slopes (log-log vs hexahedra):", {k: (round(v, 2) if v is not None else None) for k, v in summary["slopes_vs_hexahedra"].items()})
PY
