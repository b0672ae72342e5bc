#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Determinism: the main commands, run with the same inputs and seeds on 1 and on 2 threads, write
# byte-identical files. JSON files (summaries, estimate's report and parameters) are compared after
# dropping run times (keys ending in "seconds", "_s" or "_ms", or starting with "ms_") and with the
# two runs' folders in paths made equal; the ITK rigid and Demons
# baselines' metric figures inside them are compared to 1e-9 relative (ITK 5.2's v4 metric and
# Demons filter sum one partial per thread; their fields and TRE are identical). report.html embeds
# the summaries' timings and is not compared.
#
# The same commands also check that a change (a refactoring, a move of files) leaves the outputs as
# they were: record them with the old build, compare with the new one.
#   test_determinism.sh PHYSREG                      1 thread against 2 threads (ctest cli.determinism)
#   test_determinism.sh PHYSREG --record DIR         write the outputs into DIR (2 threads)
#   test_determinism.sh PHYSREG --against DIR        the outputs of this build against a recorded DIR
set -uo pipefail
physreg=$1
mode=${2:-}
target=${3:-}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failures=0
ref_root="$work/t1" # the reference run's folder as its summaries name it
run_all() { # DIR
  local out=$1 p="$physreg --quiet --no-report"
  mkdir -p "$out"
  $p phantom --preset small --seed 3 --depths 6 --no-calculix -o "$out/ph" >/dev/null &&
  $p mesh "$out/ph/rest/labels.nii.gz" --tissues "$out/ph/ground_truth_tissues.yaml" --grid 20x16x10 -o "$out/mesh.vtu" \
     --tetrahedra "$out/tets.vtu" >/dev/null &&
  $p register-compression --dataset "$out/ph" --state A --grid 12x10x6 -o "$out/rc" &&
  $p estimate --dataset "$out/ph" --train A --validate none --grid 12x10x6 --max-evaluations 2 -o "$out/params.json" \
     --report "$out/estimate.json" >/dev/null &&
  $p register-compression --dataset "$out/ph" --state A --parameters "$out/params.json" --solver condensed -o "$out/rc_condensed" &&
  $p enrich build --dataset "$out/ph" --parameters "$out/params.json" --coarse-grid 8x6x4 --depths 2,4,6 -o "$out/db.phe" >/dev/null &&
  $p enrich apply --database "$out/db.phe" --dataset "$out/ph" --parameters "$out/params.json" --state A --blend 2 -o "$out/c2f" &&
  $p register-surface --dataset "$out/ph" --visible 50 --cell-size 10 --max-steps-per-plateau 20 -o "$out/rs" >/dev/null &&
  $p register-images --dataset "$out/ph" --cycles 2 --cell-size 8 --baselines all -o "$out/ri" >/dev/null
}
case "$mode" in
  --record)
    [ -n "$target" ] && [ ! -e "$target" ] || { echo "--record needs a folder that does not exist yet"; exit 2; }
    mkdir -p "$target" && target=$(cd "$target" && pwd) # absolute: the summaries name their inputs so
    OMP_NUM_THREADS=2 run_all "$target" || { echo "FAILED: the commands"; exit 1; }
    echo "recorded $(cd "$target" && find . -type f | wc -l) files in $target"; exit 0 ;;
  --against)
    [ -d "$target" ] || { echo "--against needs a recorded folder"; exit 2; }
    OMP_NUM_THREADS=2 run_all "$work/t2" 2>"$work/err2.txt" || { echo "FAILED: the commands:"; cat "$work/err2.txt"; exit 1; }
    # The recorded run is the reference ("t1"); a symbolic link keeps the comparison below as it is.
    ref_root=$(cd "$target" && pwd)
    ln -s "$ref_root" "$work/t1"
    ;;
  "")
    for t in 1 2; do
      if ! OMP_NUM_THREADS=$t run_all "$work/t$t" 2>"$work/err$t.txt"; then
        echo "FAILED: the commands on $t thread(s):"; cat "$work/err$t.txt"; exit 1
      fi
    done ;;
  *) echo "unknown option $mode"; exit 2 ;;
esac
compared=0
while IFS= read -r f; do
  case "$f" in
    */report.html) continue ;;
    *.json) # summaries, estimate's report and parameter file
      python3 - "$work/t1/$f" "$work/t2/$f" "$ref_root" "$work/t2" "$mode" <<'PY' || { echo "FAILED: $f differs from the reference run"; failures=$((failures + 1)); }
import json, math, sys
# The runs' own folders appear in input paths: compare them as one.
a, b = (json.loads(open(p).read().replace(d, "RUN")) for p, d in ((sys.argv[1], sys.argv[3]), (sys.argv[2], sys.argv[4])))
bad, added = [], []
# Against a recording, the new build may add keys (a summary that says more), never drop or change one.
may_add = len(sys.argv) > 5 and sys.argv[5] == "--against"
def walk(x, y, path, loose):
    if isinstance(x, dict):
        if not isinstance(y, dict) or not set(x) <= set(y) or (set(x) != set(y) and not may_add): bad.append(path); return
        added.extend(f"{path}/{k}" for k in sorted(set(y) - set(x)))
        for k in x:
            if k.endswith("seconds") or k.endswith("_s") or k.startswith("ms_") or k.endswith("_ms"): continue
            walk(x[k], y[k], f"{path}/{k}", loose or k.startswith(("rigid_", "demons_")))
    elif isinstance(x, list):
        if not isinstance(y, list) or len(x) != len(y): bad.append(path); return
        for i, (p, q) in enumerate(zip(x, y)): walk(p, q, f"{path}[{i}]", loose)
    elif loose and isinstance(x, float) and isinstance(y, float):
        if not math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12): bad.append(path)
    elif x != y: bad.append(path)
walk(a, b, "", False)
if added: print(f"  {sys.argv[2].split('/t2/')[-1]}: keys added:", ", ".join(added[:10]))
if bad: print("  differing:", ", ".join(bad[:10]) or "(the top level's keys)"); sys.exit(1)
PY
      ;;
    *) cmp -s "$work/t1/$f" "$work/t2/$f" || { echo "FAILED: $f differs from the reference run"; failures=$((failures + 1)); } ;;
  esac
  compared=$((compared + 1))
done < <(cd "$work/t1/" && find . -type f | sort)
# Both runs wrote the same set of files.
diff <(cd "$work/t1/" && find . -type f | sort) <(cd "$work/t2" && find . -type f | sort) >/dev/null || { echo "FAILED: different files"; failures=$((failures + 1)); }
echo "$compared files compared, $failures differ"
[ "$compared" -gt 40 ] || { echo "FAILED: too few files compared"; exit 1; }
exit $((failures > 0))
