#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# The honest phantom's study over seeds (issue 17): for each seed, `physreg demo` makes a phantom
# whose ground-truth moduli, mesh and noise come from that seed, estimates on A, B, C, registers A–E
# and writes summary.json; this script collects the TRE of every method (training and held-out)
# into mean ± std over the seeds.
#   scripts/study_seeds.sh [--quick] OUT SEED...     e.g. scripts/study_seeds.sh --quick study 1 2 3
# Needs a built physreg (make build) and python3.
set -euo pipefail
quick=()
if [ "${1:-}" = "--quick" ]; then quick=(--quick); shift; fi
out=${1:?usage: study_seeds.sh [--quick] OUT SEED...}
shift
[ $# -ge 1 ] || { echo "give at least one seed" >&2; exit 2; }
physreg=${PHYSREG:-build/bin/physreg}
mkdir -p "$out"
for seed in "$@"; do
  echo "== seed $seed" >&2
  "$physreg" demo "${quick[@]}" --seed "$seed" -o "$out/seed$seed" > "$out/seed$seed.txt"
done
python3 - "$out" "$@" <<'PY'
import json, statistics, sys
out, seeds = sys.argv[1], sys.argv[2:]
rows = {}
for seed in seeds:
    summary = json.load(open(f"{out}/seed{seed}/summary.json"))
    for m in summary["methods"]:
        for split in ("tre_training", "tre_held_out"):
            for part in ("all", "surface", "internal"):
                rows.setdefault((m["method"], split, part), []).append(m[split][part]["mean_mm"])
def fmt(values):
    mean = statistics.mean(values)
    std = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{mean:.2f} ± {std:.2f}"
methods = []
for (method, _, _) in rows:
    if method not in methods: methods.append(method)
lines = [f"TRE (mm, mean ± std over seeds {', '.join(seeds)}; per seed the mean over the landmarks)", "",
         "| method | training A,B,C all / surface / internal | held-out D,E all / surface / internal |", "|---|---|---|"]
for method in methods:
    cells = [" / ".join(fmt(rows[(method, split, part)]) for part in ("all", "surface", "internal")) for split in ("tre_training", "tre_held_out")]
    lines.append(f"| {method} | {cells[0]} | {cells[1]} |")
text = "\n".join(lines) + "\n"
open(f"{out}/study.md", "w").write(text)
json.dump({"seeds": seeds, "rows": [{"method": k[0], "split": k[1], "part": k[2], "values_mm": v} for k, v in rows.items()]},
          open(f"{out}/study.json", "w"), indent=2)
print(text)
PY
