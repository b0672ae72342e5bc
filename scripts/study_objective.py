#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 28 item 4, one lever at a time: re-registers the pairs of a finished unaligned-pairs study
# (scripts/study_unaligned_pairs.py WORK) with the biomechanical method only, as the study ran it
# (same structures, cell size, support, cycles, seed), once per variant of `register-images`
# options, and tabulates the TRE beside the study's own label baselines (its summary.json).
#
# Usage: /usr/bin/python3 scripts/study_objective.py WORK OUT.json [--variant NAME=OPTIONS ...]
# Default variants: forward (the study's objective) and symmetric (--symmetric).
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
parser = argparse.ArgumentParser()
parser.add_argument("work")
parser.add_argument("out")
parser.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
parser.add_argument("--variant", action="append", default=None, help="NAME=extra register-images options, e.g. symmetric=--symmetric")
parser.add_argument("--cases", default="", help="comma-separated case names (default: every case of WORK)")
args = parser.parse_args()
variants = dict(v.split("=", 1) for v in (args.variant or ["forward=", "symmetric=--symmetric"]))

rows = []
for case in sorted(os.listdir(args.work)):
    if args.cases and case not in args.cases.split(","):
        continue
    folder = os.path.join(args.work, case)
    study = os.path.join(folder, "register", "summary.json")
    if not os.path.isfile(study):
        continue
    s = json.load(open(study))
    p = s["parameters"]
    base = [args.physreg, "--no-report", "--log-level", "warn", "register-images",
            "--fixed", s["inputs"]["fixed"], "--fixed-labels", s["inputs"]["fixed_labels"],
            "--moving", s["inputs"]["moving"], "--moving-labels", s["inputs"]["moving_labels"],
            "--landmarks-fixed", os.path.join(folder, "fixed_landmarks.csv"),
            "--landmarks-moving", os.path.join(os.path.dirname(s["inputs"]["moving"]), "landmarks.csv"),
            "--hold", s["model"]["hold"], "--cycles", str(p["max_cycles"]), "--cell-size", str(p["cell_size_mm"]),
            "--structures", ",".join(str(x) for x in s["structures"]), "--baselines", "none", "--json"]
    row = {"case": case}
    for method in ("rigid_labels", "demons_labels", "bspline_labels"):
        m = s["methods"].get(method, {})
        if "tre" in m:
            row[method] = {"all": m["tre"]["all"]["mean_mm"], "internal": m["tre"]["internal"]["mean_mm"]}
    for name, extra in variants.items():
        with tempfile.TemporaryDirectory() as tmp:
            started = time.time()
            result = subprocess.run(base + extra.split() + ["-o", os.path.join(tmp, "out")], capture_output=True, text=True)
            if result.returncode != 0:
                row[name] = {"status": "failed", "reason": result.stderr.strip().splitlines()[-1:]}
                continue
            out = json.loads(result.stdout[result.stdout.index("{"):])
            b = out["methods"]["biomechanical"]
            row[name] = {"all": b["tre"]["all"]["mean_mm"], "internal": b["tre"]["internal"]["mean_mm"], "seconds": b["seconds"],
                         "command_s": round(time.time() - started, 1)}
    rows.append(row)
    print(json.dumps(row), file=sys.stderr)

json.dump({"variants": variants, "rows": rows}, open(args.out, "w"), indent=2)
names = list(variants)
print("| case | " + " | ".join(f"{n} (all / internal)" for n in names) + " | rigid, labels | Demons, labels | B-spline, labels |")
print("|---|" + "---|" * (len(names) + 3))
for r in rows:
    cells = [f"{r[n]['all']:.2f} / {r[n]['internal']:.2f}" if "all" in r.get(n, {}) else "failed" for n in names]
    cells += [f"{r[m]['all']:.2f} / {r[m]['internal']:.2f}" if m in r else "-" for m in ("rigid_labels", "demons_labels", "bspline_labels")]
    print(f"| {r['case']} | " + " | ".join(cells) + " |")
for n in names:
    ok = [r[n]["internal"] for r in rows if "internal" in r.get(n, {})]
    if ok:
        print(f"{n}: mean internal TRE {sum(ok) / len(ok):.3f} mm over {len(ok)} pairs")
best = [min(r[m]["internal"] for m in ("rigid_labels", "demons_labels", "bspline_labels") if m in r) for r in rows]
print(f"best label baseline: mean internal TRE {sum(best) / len(best):.3f} mm")
