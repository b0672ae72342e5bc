#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Does the phantom generator work for every seed? Makes the dataset of each seed of a preset and
# collects, per seed: success or the error, run time, the ground-truth mesh size and every
# compression whose tool had to be enlarged (manifest "tool_adapted"). Writes OUT/seeds.json and a
# table on stdout. Not run by CI (20 seeds of the small preset take about 25 min on 2 cores).
#   scripts/study_phantom_seeds.sh [--preset small|cirs057a] OUT [FIRST LAST]    (default seeds 1 20)
# Extra phantom options go in PHANTOM_ARGS (default: --no-calculix).
set -uo pipefail
preset=small
if [ "${1:-}" = "--preset" ]; then preset="$2"; shift 2; fi
out=${1:?usage: study_phantom_seeds.sh [--preset P] OUT [FIRST LAST]}
first=${2:-1}
last=${3:-20}
physreg=${PHYSREG:-build/bin/physreg}
read -r -a extra <<< "${PHANTOM_ARGS:---no-calculix}"
mkdir -p "$out"
for seed in $(seq "$first" "$last"); do
  dir="$out/$preset-seed$seed"
  rm -rf "$dir"
  start=$(date +%s.%N)
  "$physreg" -q phantom --preset "$preset" --seed "$seed" "${extra[@]}" -o "$dir" > /dev/null 2> "$dir.err"
  status=$?
  echo "{\"seed\": $seed, \"status\": $status, \"seconds\": $(echo "$(date +%s.%N) - $start" | bc)}" > "$dir.run.json"
  echo "seed $seed: exit $status" >&2
done
python3 - "$out" "$preset" "$first" "$last" <<'PY'
import json, pathlib, statistics, sys
out, preset, first, last = pathlib.Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
rows = []
for seed in range(first, last + 1):
    run = json.loads((out / f"{preset}-seed{seed}.run.json").read_text())
    row = {"seed": seed, "ok": run["status"] == 0, "seconds": round(run["seconds"], 1)}
    if row["ok"]:
        m = json.loads((out / f"{preset}-seed{seed}" / "manifest.json").read_text())
        row["adapted"] = {s["name"]: s["tool_adapted"] for s in m["states"] if "tool_adapted" in s}
    else:
        row["error"] = (out / f"{preset}-seed{seed}.err").read_text().strip().splitlines()[-1:]
    rows.append(row)
ok = [r for r in rows if r["ok"]]
summary = {"preset": preset, "seeds": len(rows), "succeeded": len(ok),
           "seconds_mean": round(statistics.mean(r["seconds"] for r in ok), 1) if ok else None,
           "seeds_with_an_enlarged_tool": [r["seed"] for r in ok if r["adapted"]], "runs": rows}
(out / "seeds.json").write_text(json.dumps(summary, indent=2) + "\n")
print(f"{preset}: {len(ok)}/{len(rows)} seeds made a dataset; mean {summary['seconds_mean']} s; "
      f"tool enlarged on seeds {summary['seeds_with_an_enlarged_tool']}")
for r in rows:
    print(f"  seed {r['seed']:3d}: {'ok' if r['ok'] else 'FAILED'} {r['seconds']:7.1f} s  {r.get('adapted') or r.get('error') or ''}")
PY
