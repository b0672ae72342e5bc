#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 57: paper 002's segmentation-driven registration on label pairs made elsewhere, beside the
# label baselines, in one run. The data: ../shared/data/mrus-prostate-pairs (20 MR → TRUS prostate
# gland pairs, 1.5 mm voxels, frames not aligned, 3–5 paired landmark centroids per pair that the
# registration never sees; YipengHu/example-data, branch mrus; dummy data of unclear licence, used
# for tests and studies only).
#
# Each variant ("lever") is one `physreg register-images` per pair with the label maps only
# (--fixed-labels target, --moving-labels source, --baselines labels) and the variant's options;
# the default variant has no options at all. Every run reports the biomechanical answer, rigid,
# Demons and B-spline on labels (ITK) and the initial alignment: TRE = mean over the pair's
# landmarks of |P(x_i) - y_i| (mm), Dice of the gland, seconds. "centroid shift" is the pair's
# README figure (the source moved by the gland-centroid offset).
#
# Usage: /usr/bin/python3 scripts/study_prostate_pairs.py WORK_DIR [--variants default,cell3,...]
#            [--pairs mrus_obs000,...] [--physreg build/bin/physreg] [--no-docs] [--docs-only]
# Writes WORK_DIR/<variant>/<pair>/ (register-images outputs), WORK_DIR/study.json and, unless
# --no-docs, docs/results/prostate_pairs.{json,md} and docs/figures/prostate_pairs.png (needs
# python3-matplotlib). Not in CI: a pair takes 10-60 s.
import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "mrus-prostate-pairs")

# The levers of issue 57, one at a time against the defaults.
VARIANTS = {
    "default": "",
    "cell-4mm": "--cell-size 4",
    "cell-3mm": "--cell-size 3",
    "corotational": "--law corotational",
    "nodal-forces": "--parametrisation nodal-forces --anchor 0.001",  # a free gland: K needs an anchor
    "no-rest-offsets": "--no-rest-offsets",
    "symmetric": "--symmetric",
    "tight-stopping": "--tolerance 1e-6 --rms-tolerance 0 --cycles 80",
    "moduli-prior": "--moduli-prior 2",
    # The gland's Poisson ratio (default 0.45): nearly incompressible, or compressible.
    "poisson-0.49": "--tissues {work}/tissues_nu0.49.yaml",
    "poisson-0.30": "--tissues {work}/tissues_nu0.30.yaml",
}
METHODS = ["initial_alignment", "biomechanical", "rigid_labels", "demons_labels", "bspline_labels"]


def pair_entry(summary):
    out = {}
    for name in METHODS:
        m = summary["methods"].get(name)
        if m is None:
            continue
        tre = m.get("tre", {}).get("all", {}).get("mean_mm")
        dice = list(m.get("dice", {}).values())
        out[name] = {"tre_mm": tre, "dice": statistics.mean(dice) if dice else None, "seconds": m.get("seconds")}
    out["seconds_total"] = summary.get("seconds")
    out["failed_baselines"] = summary.get("failed_baselines", {})
    return out


def run_pair(physreg, case_dir, out_dir, options):
    command = [physreg, "register-images", "--fixed-labels", os.path.join(case_dir, "target_labels.nii.gz"),
               "--moving-labels", os.path.join(case_dir, "source_labels.nii.gz"),
               "--landmarks-fixed", os.path.join(case_dir, "target_landmarks.csv"),
               "--landmarks-moving", os.path.join(case_dir, "source_landmarks.csv"),
               "--baselines", "labels", "-o", out_dir, "--force"] + shlex.split(options)
    started = time.time()
    log = out_dir + ".log"
    with open(log, "w") as f:
        r = subprocess.run(command, stdout=f, stderr=subprocess.STDOUT)
    wall = time.time() - started
    if r.returncode != 0:
        tail = open(log).read()[-600:]
        return {"error": tail.strip().splitlines()[-1] if tail.strip() else f"exit {r.returncode}", "wall_s": wall}
    entry = pair_entry(json.load(open(os.path.join(out_dir, "summary.json"))))
    entry["wall_s"] = wall
    return entry


def variant_stats(pairs):
    ok = [p for p in pairs.values() if "error" not in p and "biomechanical" in p]
    if not ok:
        return {"pairs": 0}
    best = []
    bio_vs_rigid = 0
    ratio = []
    for p in ok:
        baselines = [p[m]["tre_mm"] for m in ("rigid_labels", "demons_labels", "bspline_labels") if m in p and p[m]["tre_mm"] is not None]
        b = min(baselines)
        best.append(b)
        ratio.append(p["biomechanical"]["tre_mm"] / b)
        if "rigid_labels" in p and p["biomechanical"]["tre_mm"] <= p["rigid_labels"]["tre_mm"] + 1e-9:
            bio_vs_rigid += 1
    mean = lambda k, f: statistics.mean(p[k][f] for p in ok if k in p and p[k][f] is not None)
    s = {"pairs": len(ok), "errors": len(pairs) - len(ok)}
    for m in METHODS:
        if any(m in p for p in ok):
            s[m] = {"tre_mm": mean(m, "tre_mm"), "dice": mean(m, "dice")}
    s["best_baseline_tre_mm"] = statistics.mean(best)
    s["biomechanical_over_best_baseline"] = s["biomechanical"]["tre_mm"] / s["best_baseline_tre_mm"]
    s["median_pair_ratio"] = statistics.median(ratio)
    s["pairs_biomechanical_at_most_rigid"] = bio_vs_rigid
    s["pairs_biomechanical_at_most_best"] = sum(1 for r in ratio if r <= 1.0 + 1e-9)
    s["seconds_median"] = statistics.median(p["seconds_total"] for p in ok)
    s["seconds_max"] = max(p["seconds_total"] for p in ok)
    return s


def write_docs(study):
    results = os.path.join(ROOT, "docs", "results")
    os.makedirs(results, exist_ok=True)
    with open(os.path.join(results, "prostate_pairs.json"), "w") as f:
        json.dump(study, f, indent=1)
    v = study["variants"]
    lines = ["# MR → TRUS prostate gland pairs (issue 57)", "",
             "Generated by `scripts/study_prostate_pairs.py` on " + study["date"] + " from `../shared/data/mrus-prostate-pairs` "
             "(20 public dummy pairs, YipengHu/example-data branch mrus; landmarks never seen by the registration). "
             "`physreg register-images` with the label maps only and `--baselines labels`; TRE = mean landmark error per pair, "
             "then the mean over pairs (mm); Dice of the gland. Best baseline: the lowest of rigid, Demons and B-spline on labels per pair.", ""]
    lines += ["| variant | options | pairs | biomechanical TRE (mm) | best baseline (mm) | ratio | pairs ≤ rigid | Dice | "
              "rigid (mm) | Demons (mm) | B-spline (mm) | alignment (mm) | median s |", "|" + "---|" * 13]
    for name, e in v.items():
        s = e["stats"]
        if not s.get("pairs"):
            lines.append(f"| {name} | `{e['options']}` | 0 | – |" + " – |" * 9)
            continue
        g = lambda m: f"{s[m]['tre_mm']:.2f}" if m in s else "–"
        lines.append(f"| {name} | `{e['options'] or '(none)'}` | {s['pairs']} | {s['biomechanical']['tre_mm']:.2f} | {s['best_baseline_tre_mm']:.2f} | "
                     f"{s['biomechanical_over_best_baseline']:.2f}× | {s['pairs_biomechanical_at_most_rigid']}/{s['pairs']} | "
                     f"{s['biomechanical']['dice']:.3f} | {g('rigid_labels')} | {g('demons_labels')} | {g('bspline_labels')} | "
                     f"{g('initial_alignment')} | {s['seconds_median']:.1f} |")
    d = v.get("default", {}).get("pairs", {})
    if d:
        lines += ["", "## Default options, per pair", "",
                  "| pair | centroid shift | alignment | biomechanical | rigid | Demons | B-spline | Dice bio / Demons | s |", "|" + "---|" * 9]
        for pair, p in d.items():
            if "error" in p:
                lines.append(f"| {pair} | {study['centroid_shift'].get(pair, float('nan')):.2f} | error: {p['error']} |" + " |" * 6)
                continue
            g = lambda m: f"{p[m]['tre_mm']:.2f}" if m in p and p[m]["tre_mm"] is not None else "–"
            dd = lambda m: f"{p[m]['dice']:.3f}" if m in p else "–"
            lines.append(f"| {pair} | {study['centroid_shift'].get(pair, float('nan')):.2f} | {g('initial_alignment')} | {g('biomechanical')} | "
                         f"{g('rigid_labels')} | {g('demons_labels')} | {g('bspline_labels')} | {dd('biomechanical')} / {dd('demons_labels')} | "
                         f"{p['seconds_total']:.1f} |")
    with open(os.path.join(results, "prostate_pairs.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("no matplotlib: figure not drawn", file=sys.stderr)
        return
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    if d:
        names = [k for k, p in d.items() if "error" not in p]
        x = range(len(names))
        for k, (m, label) in enumerate([("biomechanical", "biomechanical"), ("rigid_labels", "rigid (labels)"),
                                        ("demons_labels", "Demons (labels)"), ("bspline_labels", "B-spline (labels)")]):
            axes[0].bar([i + 0.2 * k - 0.3 for i in x], [d[n][m]["tre_mm"] if m in d[n] else 0 for n in names], 0.2, label=label)
        axes[0].plot(list(x), [study["centroid_shift"].get(n, float("nan")) for n in names], "k_", markersize=12, label="centroid shift")
        axes[0].set_xticks(list(x))
        axes[0].set_xticklabels([n.replace("mrus_obs", "") for n in names], rotation=90)
        axes[0].set_ylabel("mean landmark TRE (mm)")
        axes[0].set_title("default options, per pair")
        axes[0].legend(fontsize=8)
    names = [n for n, e in v.items() if e["stats"].get("pairs")]
    axes[1].barh(names, [v[n]["stats"]["biomechanical_over_best_baseline"] for n in names], color="tab:blue")
    axes[1].axvline(1.0, color="k", lw=1)
    axes[1].axvline(0.9, color="tab:red", lw=1, ls="--", label="target 0.9×")
    axes[1].set_xlabel("biomechanical TRE / best label baseline (mean over pairs)")
    axes[1].set_title("one lever at a time")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.join(ROOT, "docs", "figures"), exist_ok=True)
    fig.savefig(os.path.join(ROOT, "docs", "figures", "prostate_pairs.png"), dpi=110)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("work")
    ap.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
    ap.add_argument("--variants", default="default", help="comma-separated, of: " + ", ".join(VARIANTS) + "; or NAME=OPTIONS")
    ap.add_argument("--pairs", default="", help="only these case names, comma-separated")
    ap.add_argument("--no-docs", action="store_true")
    ap.add_argument("--docs-only", action="store_true", help="redraw the docs from WORK_DIR/study.json")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    study_path = os.path.join(a.work, "study.json")
    if a.docs_only:
        write_docs(json.load(open(study_path)))
        return
    if not os.path.isdir(DATA):
        sys.exit(f"{DATA}: not found (the study needs ../shared/data)")
    cases = sorted(os.listdir(os.path.join(DATA, "cases")))
    if a.pairs:
        cases = [c for c in cases if c in a.pairs.split(",")]
    study = json.load(open(study_path)) if os.path.exists(study_path) else {"variants": {}}
    study["date"] = time.strftime("%Y-%m-%d")
    study["centroid_shift"] = {}
    for c in cases:
        meta = json.load(open(os.path.join(DATA, "cases", c, "meta.json")))
        shift = meta.get("landmark_error_mm", {}).get("gland_centroid_shift", {}).get("mean")
        if shift is not None:
            study["centroid_shift"][c] = shift
    for nu in ("0.49", "0.30"):
        with open(os.path.join(a.work, f"tissues_nu{nu}.yaml"), "w") as f:
            f.write(f"tissues:\n  - {{label: 1, name: gland, young_modulus_pa: 3000, poisson_ratio: {nu}}}\n")
    for spec in a.variants.split(","):
        name, options = (spec.split("=", 1) if "=" in spec else (spec, VARIANTS[spec]))
        options = options.replace("{work}", os.path.abspath(a.work))
        entry = study["variants"].setdefault(name, {"options": options, "pairs": {}})
        entry["options"] = options
        for c in cases:
            out = os.path.join(a.work, name, c)
            os.makedirs(os.path.dirname(out), exist_ok=True)
            p = run_pair(a.physreg, os.path.join(DATA, "cases", c), out, options)
            entry["pairs"][c] = p
            if "error" in p:
                print(f"{name:16s} {c}: error: {p['error']}", flush=True)
            else:
                b = p.get("biomechanical", {})
                print(f"{name:16s} {c}: bio {b.get('tre_mm', float('nan')):.2f} mm Dice {b.get('dice', float('nan')):.3f} | " +
                      " ".join(f"{m.split('_')[0]} {p[m]['tre_mm']:.2f}" for m in METHODS[2:] if m in p) + f" | {p['seconds_total']:.1f} s", flush=True)
        entry["stats"] = variant_stats(entry["pairs"])
        print(name, json.dumps(entry["stats"]), flush=True)
        with open(study_path, "w") as f:
            json.dump(study, f, indent=1)
    if not a.no_docs:
        write_docs(study)


if __name__ == "__main__":
    main()
