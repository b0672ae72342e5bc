#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# The figure of docs/results/unaligned_pairs_drawn_support.json (issue 46 item 6, paper 002): the biomechanical
# answer's TRE against the rigid registration's, one point per pair. Usage: /usr/bin/python3 scripts/plot_unaligned_pairs.py (from the root)
import json, matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
d = json.load(open("docs/results/unaligned_pairs_drawn_support.json"))
fig, ax = plt.subplots(figsize=(6.2, 5.2))
colours = {"prostate-like": "tab:purple", "lung-like": "tab:green", "liver-small-preset": "tab:blue"}
for organ, colour in colours.items():
    sel = [r for r in d["cases"] if r["case"].startswith(organ) and "tre_mm" in r["methods"].get("biomechanical", {})]
    ax.scatter([r["methods"]["rigid_labels"]["tre_mm"] for r in sel], [r["methods"]["biomechanical"]["tre_mm"] for r in sel], c=colour, s=30, label=f"{organ} ({len(sel)})")
top = max(max(r["methods"]["rigid_labels"]["tre_mm"], r["methods"]["biomechanical"]["tre_mm"]) for r in d["cases"]) * 1.05
ax.plot([0, top], [0, top], "k--", lw=0.8, label="= rigid (labels)")
ax.set_xlabel("TRE of the rigid registration of the labels (mm)")
ax.set_ylabel("TRE of register-images' biomechanical answer (mm)")
ax.set_title(f"register-images defaults, {len(d['cases'])} unaligned pairs, truth held where drawn", fontsize=10)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig("docs/figures/unaligned_pairs_drawn_support.png", dpi=110)
