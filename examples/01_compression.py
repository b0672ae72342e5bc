#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Example: make a small phantom, predict one of its compressions with paper 000's heterogeneous
model, and plot the target registration error per landmark (matplotlib).

    PYTHONPATH=build/python /usr/bin/python3 examples/01_compression.py WORK_DIR [DATASET STATE]

Without DATASET it makes the small phantom in WORK_DIR/phantom (about a minute on two cores) and
predicts its compression A. On the small preset the tool's travel barely reaches the liver of the
registering model, so the model stays almost at rest there; the demo's phantom shows the model at
work: `... WORK_DIR demo-out/phantom D`. Writes WORK_DIR/compression_STATE and WORK_DIR/tre_STATE.png.
"""
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import physreg  # noqa: E402


def progress(label, fraction, message):
    print(f"\r{label:>22}: {100 * fraction:5.1f} %  {message[:50]:<50}", end="", flush=True)


def main(work, dataset=None, state="A"):
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    if dataset is None:
        dataset = work / "phantom"
        if not (dataset / "manifest.json").exists():
            physreg.phantom(dataset, preset="small", seed=7, depths="8", no_calculix=True, progress=progress)
            print()
    dataset = Path(dataset)
    out = work / f"compression_{state}"
    # Paper 000's 74 × 54 × 18 grid needs the full-size phantom; the small one gets a coarser grid.
    small = json.loads((dataset / "manifest.json").read_text())["generator"]["preset"] == "small"
    summary = physreg.register_compression(out, dataset=dataset, state=state, grid="16x12x8" if small else None,
                                           progress=progress, force=True)
    print()
    # Predicted landmarks against the phantom's truth, matched by name.
    names, predicted, _ = physreg.read_landmarks(out / "landmarks.csv")
    truth_names, truth, types = physreg.read_landmarks(dataset / "states" / state / "landmarks.csv")
    order = [truth_names.index(n) for n in names]
    result = physreg.tre(predicted, truth[order])
    _, rest, _ = physreg.read_landmarks(dataset / "rest" / "landmarks.csv")
    at_rest = physreg.tre(rest[order], truth[order])  # not registering at all

    colour = {"surface": "tab:green", "tumour": "tab:red", "vessel": "tab:blue"}
    fig, ax = plt.subplots(figsize=(9, 3.5), layout="constrained")
    x = np.arange(len(names))
    ax.bar(x - 0.2, at_rest["errors_mm"], 0.4, color="lightgray", label=f"at rest (mean {at_rest['mean_mm']:.2f} mm)")
    ax.bar(x + 0.2, result["errors_mm"], 0.4, color=[colour.get(types[i], "gray") for i in order],
           label=f"heterogeneous model (mean {result['mean_mm']:.2f} mm)")
    ax.set_xticks(x, names, rotation=90, fontsize=7)
    ax.set_ylabel("TRE (mm)")
    ax.set_title(f"Compression {state} of {dataset.name}: model solved in {summary.get('seconds', float('nan')):.2f} s")
    ax.legend(fontsize=8)
    png = work / f"tre_{state}.png"
    fig.savefig(png, dpi=120)
    print(f"TRE mean {result['mean_mm']:.2f} mm (max {result['max_mm']:.2f}); at rest {at_rest['mean_mm']:.2f} mm → {png}")
    return result, at_rest


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "example-out", *sys.argv[2:4])
