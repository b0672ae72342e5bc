#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 46 item 6, paper 000: tool states our defaults were not built for. Every dataset is drawn at
# random from a seed, and `register-compression` runs with its default options (the body model,
# literature moduli, dynamic relaxation), never told what was drawn:
#   - the body: the small synthetic phantom (a drawn seed) or the real CIRS-057A CT label map in
#     ../shared/data (a body another scanner and another segmentation made);
#   - the tool: a sphere of radius 10-30 mm;
#   - the depth: three states per body at 0.3-1.5x the tool's radius past first skin contact, one of
#     them at least 1.2x (deeper than the radius: where the tool used to pass through the skin);
#   - the material the truth's moduli are drawn around: paper000, healthy or cirrhotic.
# The truth is the phantom's ground truth: Mooney-Rivlin tetrahedra on their own CGAL mesh, drawn
# moduli, Newton with frictionless node and face contact: another element, law, mesh and solver
# than the registering hexahedral Neo-Hookean model. States the generator cannot make (the truth
# folds, a depth over 60 % of the tissue) are recorded as refused by the generator, not counted.
#
# Usage: /usr/bin/python3 scripts/study_tool_states.py [--states 30] [--seed 46] [--report-only] WORK_DIR
# Cases are cached in WORK_DIR/cases/*.json (a rerun continues). Writes WORK_DIR/study.json and,
# unless --no-docs, docs/results/tool_states.{json,md} and docs/figures/tool_states.png (needs
# Debian's python3-matplotlib). About 1-2 min per state on 2 cores.
import argparse
import json
import os
import random
import statistics
import subprocess
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
parser = argparse.ArgumentParser()
parser.add_argument("work")
parser.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
parser.add_argument("--states", type=int, default=30, help="registered states to reach (datasets are drawn until then)")
parser.add_argument("--max-datasets", type=int, default=20)
parser.add_argument("--seed", type=int, default=46)
parser.add_argument("--no-docs", action="store_true")
parser.add_argument("--report-only", action="store_true", help="redraw tables and figure from the cached cases")
args = parser.parse_args()
os.makedirs(os.path.join(args.work, "cases"), exist_ok=True)
rng = random.Random(args.seed)
CT_LABELS = os.path.join(os.path.dirname(ROOT), "shared", "data", "cirs057a-ct", "labels.nii.gz")


def draw_dataset(index):
    body = "cirs_ct" if os.path.exists(CT_LABELS) and rng.random() < 0.3 else "small"
    radius = rng.choice([10, 12, 15, 20, 25, 30])
    factors = sorted([rng.uniform(0.3, 1.2), rng.uniform(0.3, 1.5), rng.uniform(1.2, 1.5)])
    return {
        "id": f"d{index:02d}", "body": body, "seed": rng.randint(1, 10000), "radius_mm": radius,
        "depths_mm": [round(f * radius, 1) for f in factors],
        "materials": rng.choice(["paper000", "healthy", "cirrhotic"]),
    }


def run(cmd, log):
    start = time.time()
    with open(log, "w") as f:
        rc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=f, text=True).returncode
    return rc, time.time() - start


def last_error(log):
    lines = [l.strip() for l in open(log) if l.strip()]
    errors = [l for l in lines if "error" in l.lower()]
    return (errors or lines or [""])[-1][:400]


def warnings_of(log):
    return [l.strip()[:300] for l in open(log) if "[warning]" in l]


def run_dataset(spec):
    folder = os.path.join(args.work, spec["id"])
    body = (["--preset", "small"] if spec["body"] == "small" else
            ["--from-labels", CT_LABELS, "--ground-truth-size", "7,18"])
    cmd = [args.physreg, "-q", "--no-report", "phantom", *body, "--seed", str(spec["seed"]),
           "--tool-radius", str(spec["radius_mm"]), "--depths", ",".join(str(d) for d in spec["depths_mm"]),
           "--materials", spec["materials"], "--insufflation-pa", "0", "--no-calculix", "-o", folder, "--force"]
    previous = folder + ".phantom.json"
    if os.path.exists(os.path.join(folder, "manifest.json")) and os.path.exists(previous) and json.load(open(previous))["cmd"] == cmd:
        rc, seconds = 0, json.load(open(previous))["seconds"]  # the dataset made before: only the registrations run again
    else:
        rc, seconds = run(cmd, folder + ".phantom.log")
        json.dump({"cmd": cmd, "seconds": seconds, "exit": rc}, open(previous, "w"))
    result = dict(spec, phantom_exit=rc, phantom_s=round(seconds, 1), states=[])
    if rc != 0:
        result["phantom_error"] = last_error(folder + ".phantom.log")
        return result
    manifest = json.load(open(os.path.join(folder, "manifest.json")))
    for state in manifest["states"]:
        if state.get("kind") != "compression":
            continue
        name = state["name"]
        out = os.path.join(folder, f"register_{name}")
        log = out + ".log"
        cmd = [args.physreg, "-q", "--no-report", "register-compression", "--dataset", folder,
               "--state", name, "-o", out, "--force", "--json"]
        start = time.time()
        with open(log, "w") as f:
            proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=f, text=True)
        row = {"state": name, "exit": proc.returncode, "seconds": round(time.time() - start, 1),
               "depth_mm": state.get("depth_mm"), "tool_radius_mm": state.get("tool", {}).get("radius_mm"),
               "tool_adapted": state.get("tool_adapted"), "truth_max_displacement_mm": state.get("max_displacement_mm"),
               "warnings": warnings_of(log)}
        if proc.returncode == 0:
            summary = json.loads(proc.stdout[proc.stdout.index("{"):proc.stdout.rindex("}") + 1])
            row["tre_mm"] = summary["tre_against_dataset"]["all"]["mean_mm"]
            row["tre_at_rest_mm"] = summary["tre_landmarks_at_rest"]["all"]["mean_mm"]
            row["tre_tumour_mm"] = summary["tre_against_dataset"].get("tumour", {}).get("mean_mm")
            row["tumour_at_rest_mm"] = summary["tre_landmarks_at_rest"].get("tumour", {}).get("mean_mm")
            row["ratio"] = row["tre_mm"] / row["tre_at_rest_mm"]
            row["model_max_displacement_mm"] = summary.get("max_displacement_mm")
        else:
            row["error"] = last_error(log)
        result["states"].append(row)
    return result


cases = []
index = 0
registered = 0
while not args.report_only and registered < args.states and index < args.max_datasets:
    spec = draw_dataset(index)
    index += 1
    cache = os.path.join(args.work, "cases", spec["id"] + ".json")
    if os.path.exists(cache) and json.load(open(cache))["seed"] == spec["seed"]:
        result = json.load(open(cache))
    else:
        print(f"{spec['id']}: {spec['body']} seed {spec['seed']}, sphere r {spec['radius_mm']} mm, depths {spec['depths_mm']} mm", flush=True)
        result = run_dataset(spec)
        json.dump(result, open(cache, "w"), indent=1)
    cases.append(result)
    registered += sum(1 for s in result["states"] if s["exit"] == 0)
if args.report_only:
    folder = os.path.join(args.work, "cases")
    cases = [json.load(open(os.path.join(folder, f))) for f in sorted(os.listdir(folder)) if f.endswith(".json")]

rows = [dict(s, dataset=c["id"], body=c["body"], materials=c["materials"]) for c in cases for s in c["states"]]
done = [r for r in rows if r["exit"] == 0]
stopped = [r for r in rows if r["exit"] != 0]
ratios = [r["ratio"] for r in done]
deep = [r for r in done if r["depth_mm"] and r["tool_radius_mm"] and r["depth_mm"] > r["tool_radius_mm"]]
summary = {
    "datasets": len(cases), "datasets_refused_by_generator": sum(1 for c in cases if c["phantom_exit"] != 0),
    "states": len(rows), "registered": len(done), "stopped_with_an_error": len(stopped),
    "worse_than_at_rest": sum(1 for r in ratios if r > 1.0),
    "median_ratio": round(statistics.median(ratios), 3) if ratios else None,
    "mean_ratio": round(statistics.mean(ratios), 3) if ratios else None,
    "median_ratio_deeper_than_radius": round(statistics.median([r["ratio"] for r in deep]), 3) if deep else None,
    "states_deeper_than_radius": len(deep),
    "with_warnings": sum(1 for r in done if r["warnings"]),
    "seconds_median": round(statistics.median(r["seconds"] for r in done), 1) if done else None,
}
json.dump({"seed": args.seed, "summary": summary, "cases": cases}, open(os.path.join(args.work, "study.json"), "w"), indent=1)
print(json.dumps(summary, indent=1))

if not args.no_docs and rows:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.2, 5.2))
    top = max([r["tre_at_rest_mm"] for r in done] + [r["tre_mm"] for r in done] + [1.0]) * 1.1
    ax.plot([0, top], [0, top], color="0.6", lw=1, label="= at rest")
    ax.plot([0, top], [0, top / 2], color="0.8", lw=1, ls="--", label="0.5x at rest")
    for flag, colour, label in ((False, "tab:blue", "no warning"), (True, "tab:orange", "a warning in the log")):
        pts = [r for r in done if bool(r["warnings"]) == flag]
        ax.scatter([r["tre_at_rest_mm"] for r in pts], [r["tre_mm"] for r in pts], s=[20 + 1.2 * r["tool_radius_mm"] for r in pts],
                   c=colour, alpha=0.8, edgecolors="k", linewidths=0.4, label=f"{label} ({len(pts)})")
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_xlabel("mean TRE with the landmarks left at rest (mm)")
    ax.set_ylabel("mean TRE of register-compression, defaults (mm)")
    ax.set_title(f"Paper 000 on {len(done)} tool states it was not built for\n(marker size: tool radius 10-30 mm; truth: another model)", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    os.makedirs(os.path.join(ROOT, "docs", "figures"), exist_ok=True)
    fig.savefig(os.path.join(ROOT, "docs", "figures", "tool_states.png"), dpi=110)
    os.makedirs(os.path.join(ROOT, "docs", "results"), exist_ok=True)
    json.dump({"seed": args.seed, "summary": summary, "cases": cases}, open(os.path.join(ROOT, "docs", "results", "tool_states.json"), "w"), indent=1)
    with open(os.path.join(ROOT, "docs", "results", "tool_states.md"), "w") as f:
        f.write("# Paper 000 on tool states it was not built for (issue 46 item 6)\n\n")
        f.write(f"Made by `scripts/study_tool_states.py` (seed {args.seed}); `register-compression` with its default options. "
                "Truth: the phantom's Mooney-Rivlin tetrahedra (Newton, frictionless contact). TRE: mean over the dataset's 25 landmarks, mm.\n\n")
        f.write("| summary | value |\n|---|---|\n")
        for k, v in summary.items():
            f.write(f"| {k.replace('_', ' ')} | {v} |\n")
        f.write("\n| dataset | body | material | state | r (mm) | depth (mm) | depth/r | exit | TRE (mm) | at rest (mm) | ratio | tumours (mm) | tumours at rest (mm) | s | warnings / error |\n")
        f.write("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
        for c in cases:
            if c["phantom_exit"] != 0:
                f.write(f"| {c['id']} | {c['body']} | {c['materials']} | (generator) | {c['radius_mm']} | {c['depths_mm']} | | {c['phantom_exit']} | | | | | | {c['phantom_s']} | {c.get('phantom_error', '')} |\n")
                continue
            for r in c["states"]:
                fmt = lambda v: "" if v is None else f"{v:.3f}"  # noqa: E731
                note = r.get("error") or "; ".join(r["warnings"])
                depth_ratio = f"{r['depth_mm'] / r['tool_radius_mm']:.2f}" if r["depth_mm"] and r["tool_radius_mm"] else ""
                f.write(f"| {c['id']} | {c['body']} | {c['materials']} | {r['state']} | {r['tool_radius_mm']} | {r['depth_mm']} | {depth_ratio} | {r['exit']} | "
                        f"{fmt(r.get('tre_mm'))} | {fmt(r.get('tre_at_rest_mm'))} | {fmt(r.get('ratio'))} | {fmt(r.get('tre_tumour_mm'))} | "
                        f"{fmt(r.get('tumour_at_rest_mm'))} | {r['seconds']} | {note.replace('|', '/')} |\n")
