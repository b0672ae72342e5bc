#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Issue 56: paper 001's registration to a partial surface on public data made elsewhere, beside the
# published peer, in one run. The data: ../shared/data/adjoint-liver (Mestdagh & Cotin, MICCAI 2022,
# GPL-3.0): a tetrahedral liver (3 046 nodes) pushed by a tool, 9 sequences of 50 frames (linear
# and Neo-Hookean generators), a 500-point noise-free cloud over part of the pushed surface per
# frame, the true position of every node. The peer is the authors' own code (peer/run_peer.py:
# linear elasticity, forces on the sequence's force patch, Dirichlet nodes held, adjoint L-BFGS).
#
# Three physreg rows per frame, each `physreg register-surface` with default options otherwise:
#   default      the mesh and the cloud, nothing else;
#   supports     the generator's 106 Dirichlet nodes as --support-nodes;
#   peer-info    the Dirichlet nodes and the sequence's force patch as --load-nodes (the peer's
#                information: where the organ is held and where the tool may press).
# TRE: mean |u - u_true| over the 604 interior nodes (not on the boundary surface), mm, the
# peer's README's figure; "at rest" is u = 0.
#
# Usage: /usr/bin/python3 scripts/study_adjoint_liver.py WORK_DIR [--frames 0,10,20,30,40]
#            [--sequences linear/s1,...] [--rows default,supports,peer-info] [--physreg build/bin/physreg]
#            [--extra "--method adjoint"] [--tag NAME] [--no-peer] [--no-docs]
# Writes WORK_DIR/study.json and, unless --no-docs, docs/results/adjoint_liver.{json,md} and
# docs/figures/adjoint_liver.png. Needs python3-numpy, python3-scipy, python3-meshio (the peer) and
# python3-matplotlib (the figure). Not in CI: each physreg row takes 5-60 s, a frame's peer 2-4 s.
import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "adjoint-liver")
SEQUENCES = ["linear/s1", "linear/s2", "linear/s3", "linear/s4", "linear/s5",
             "neohookean/s1", "neohookean/s2", "neohookean/s4", "neohookean/s5"]
ROWS = ["default", "supports", "peer-info"]


def read_msh_tetrahedra(path):
    """Nodes (m) and tetrahedra (0-based) of the package's Gmsh 2.2 ASCII liver."""
    with open(path) as f:
        lines = f.read().split("\n")
    i = lines.index("$Nodes")
    n = int(lines[i + 1])
    nodes = np.array([[float(v) for v in lines[i + 2 + k].split()[1:4]] for k in range(n)])
    ids = [int(lines[i + 2 + k].split()[0]) for k in range(n)]
    if ids != list(range(1, n + 1)):
        sys.exit(f"{path}: node ids are not 1..{n} in order")
    i = lines.index("$Elements")
    m = int(lines[i + 1])
    tets = []
    for k in range(m):
        w = [int(v) for v in lines[i + 2 + k].split()]
        if w[1] == 4:
            tags = w[2]
            tets.append([v - 1 for v in w[3 + tags:3 + tags + 4]])
    return nodes, np.array(tets, dtype=np.int64)


def write_msh_mm(path, nodes_mm, tets):
    with open(path, "w") as f:
        f.write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n%d\n" % len(nodes_mm))
        for k, p in enumerate(nodes_mm):
            f.write("%d %.9f %.9f %.9f\n" % (k + 1, p[0], p[1], p[2]))
        f.write("$EndNodes\n$Elements\n%d\n" % len(tets))
        for k, t in enumerate(tets):
            f.write("%d 4 2 1 1 %d %d %d %d\n" % (k + 1, t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1))
        f.write("$EndElements\n")


def boundary_nodes(tets):
    f = np.vstack([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]], tets[:, [1, 2, 3]]])
    u, c = np.unique(np.sort(f, axis=1), axis=0, return_counts=True)
    return np.unique(u[c == 1])


def write_points(path, names, points_mm):
    with open(path, "w") as f:
        f.write("name,x,y,z\n")
        for n, p in zip(names, points_mm):
            f.write("%s,%.6f,%.6f,%.6f\n" % (n, p[0], p[1], p[2]))


def write_ids(path, ids):
    with open(path, "w") as f:
        f.write("\n".join(str(int(i)) for i in ids) + "\n")


def prepare(work):
    mesh_dir = os.path.join(DATA, "data", "liver", "mesh-default")
    nodes_m, tets = read_msh_tetrahedra(os.path.join(mesh_dir, "liver.msh"))
    nodes = 1000.0 * nodes_m
    common = os.path.join(work, "common")
    os.makedirs(common, exist_ok=True)
    write_msh_mm(os.path.join(common, "liver_mm.msh"), nodes, tets)
    write_ids(os.path.join(common, "dirichlet.txt"), np.load(os.path.join(mesh_dir, "dirichlet-vertices.npy")))
    interior = np.setdiff1d(np.arange(len(nodes)), boundary_nodes(tets))
    names = ["n%d" % i for i in interior]
    write_points(os.path.join(common, "targets_rest.csv"), names, nodes[interior])
    return nodes, interior, names, common


def run(command, log):
    started = time.time()
    with open(log, "w") as out:
        r = subprocess.run(command, stdout=subprocess.PIPE, stderr=out, text=True)
    return r, time.time() - started


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("work")
    ap.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
    ap.add_argument("--frames", default="0,10,20,30,40")
    ap.add_argument("--sequences", default=",".join(SEQUENCES))
    ap.add_argument("--rows", default=",".join(ROWS))
    ap.add_argument("--extra", default="", help="further register-surface options for every row (a variant's study)")
    ap.add_argument("--tag", default="", help="name of this variant in the JSON (with --extra)")
    ap.add_argument("--no-peer", action="store_true")
    ap.add_argument("--reuse-peer", action="store_true", help="read the peer's answer where WORK_DIR already holds it (the peer is deterministic)")
    ap.add_argument("--no-docs", action="store_true")
    ap.add_argument("--docs-only", action="store_true", help="re-read WORK_DIR's summaries (no run) and write the docs")
    a = ap.parse_args()
    if a.docs_only:
        results = json.load(open(os.path.join(a.work, "study.json")))["frames"]
        for e in results:
            case = os.path.join(a.work, "%s_f%02d" % (e["sequence"].replace("/", "_"), e["frame"]))
            for row, r in e["rows"].items():
                if not r.get("failed"):
                    e["rows"][row] = row_entry(os.path.join(case, row, "summary.json"), r["seconds"])
        write_docs(results, a)
        return
    if not os.path.isdir(DATA):
        sys.exit(f"{DATA} is missing: this study needs ../shared/data/adjoint-liver")
    os.makedirs(a.work, exist_ok=True)
    nodes, interior, names, common = prepare(a.work)
    frames = [int(f) for f in a.frames.split(",")]
    rows_wanted = a.rows.split(",")
    results = []
    out_json = os.path.join(a.work, "study%s.json" % ("_" + a.tag if a.tag else ""))
    for seq in a.sequences.split(","):
        model, name = seq.split("/")
        seq_dir = os.path.join(DATA, "data", "liver", "sequences", model, name)
        positions = np.load(os.path.join(seq_dir, "positions-default.npy"))
        load_nodes = os.path.join(a.work, "common", f"{model}_{name}_force_patch.txt")
        write_ids(load_nodes, np.load(os.path.join(seq_dir, "forces-vertices-default.npy")))
        for k in frames:
            case = os.path.join(a.work, f"{model}_{name}_f{k:02d}")
            os.makedirs(case, exist_ok=True)
            true_u = 1000.0 * positions[k] - nodes
            cloud = 1000.0 * np.loadtxt(os.path.join(seq_dir, "pointclouds", f"pc{k:02d}.txt"))
            with open(os.path.join(case, "cloud.csv"), "w") as f:
                f.write("x,y,z\n")
                for p in cloud:
                    f.write("%.6f,%.6f,%.6f\n" % tuple(p))
            write_points(os.path.join(case, "targets_true.csv"), names, nodes[interior] + true_u[interior])
            at_rest = float(np.linalg.norm(true_u[interior], axis=1).mean())
            entry = {"sequence": seq, "frame": k, "at_rest_mm": at_rest,
                     "largest_true_displacement_mm": float(np.linalg.norm(true_u, axis=1).max()), "rows": {}}
            if not a.no_peer:
                peer_csv = os.path.join(case, "peer.csv")
                if a.reuse_peer and os.path.exists(peer_csv) and os.path.exists(os.path.join(case, "peer.json")):
                    r, sec = subprocess.CompletedProcess([], 0), json.load(open(os.path.join(case, "peer.json")))["run_time_s"]["total"]
                else:
                    r, sec = run(["/usr/bin/python3", os.path.join(DATA, "peer", "run_peer.py"), DATA, "--model", model, "--sequence", name,
                                  "--frame", str(k), "--out", peer_csv], os.path.join(case, "peer.log"))
                if r.returncode == 0:
                    u = np.loadtxt(peer_csv, delimiter=",", skiprows=1)[:, 1:4]
                    entry["peer"] = {"tre_mm": float(np.linalg.norm(u[interior] - true_u[interior], axis=1).mean()), "seconds": sec}
                else:
                    entry["peer"] = {"failed": True}
            for row in rows_wanted:
                out = os.path.join(case, row + ("_" + a.tag if a.tag else ""))
                cmd = [a.physreg, "-q", "--no-report", "register-surface", "--model", os.path.join(common, "liver_mm.msh"),
                       "--cloud", os.path.join(case, "cloud.csv"), "--landmarks", os.path.join(common, "targets_rest.csv"),
                       "--landmarks-truth", os.path.join(case, "targets_true.csv"), "-o", out, "--force"]
                if row in ("supports", "peer-info"):
                    cmd += ["--support-nodes", os.path.join(common, "dirichlet.txt")]
                if row == "peer-info":
                    cmd += ["--load-nodes", load_nodes]
                cmd += shlex.split(a.extra)
                r, sec = run(cmd, out + ".log")
                if r.returncode != 0:
                    entry["rows"][row] = {"failed": True, "seconds": sec, "error": open(out + ".log").read()[-400:]}
                    print(f"{seq} f{k} {row}: FAILED ({sec:.0f} s)", file=sys.stderr)
                    continue
                entry["rows"][row] = row_entry(os.path.join(out, "summary.json"), sec)
                answer = entry["rows"][row]["answer"]
                print(f"{seq} f{k} {row}: {answer} {entry['rows'][row]['tre_mm']:.2f} mm (at rest {at_rest:.2f}, peer "
                      f"{entry.get('peer', {}).get('tre_mm', float('nan')):.2f}) {sec:.0f} s", file=sys.stderr)
            results.append(entry)
            json.dump({"tag": a.tag, "extra": a.extra, "frames": results}, open(out_json, "w"), indent=1)
    if not a.no_docs:
        write_docs(results, a)


def row_entry(summary_path, seconds):
    """One physreg row from its summary.json: the answer's TRE, every method's, the safeguard, and the
    halves' precision (the predicted error, issue 56 item 6)."""
    s = json.load(open(summary_path))
    answer = s["safeguard"]["answer"]
    methods = {m: {"tre_mm": v["tre"]["all"]["mean_mm"], "cloud_mm": v["cloud_to_model_mm"]["mean"],
                   "rotation_deg": v["implied_rigid_motion"]["rotation_deg"]}
               for m, v in s["methods"].items() if "tre" in v}
    u = s.get("uncertainty", {})
    return {"answer": answer, "tre_mm": methods[answer]["tre_mm"], "flags": s["safeguard"]["flags"], "notes": s["safeguard"].get("notes", []),
            "runner_up": s["safeguard"].get("runner_up"), "margin_mm": s["safeguard"].get("margin_mm"),
            "support": s.get("support"), "methods": methods, "seconds": seconds, "program_seconds": s.get("seconds"),
            "precision_mm": u.get("targets_precision_mean_mm", u.get("precision_mm"))}


def spearman(x, y):
    rank = lambda v: np.argsort(np.argsort(v)).astype(float)
    if len(x) < 3:
        return None
    return float(np.corrcoef(rank(np.asarray(x)), rank(np.asarray(y)))[0, 1])


def ratio_stats(values):
    v = sorted(values)
    return {"n": len(v), "median": statistics.median(v) if v else None, "max": max(v) if v else None, "mean": statistics.fmean(v) if v else None}


def row_stats(entries, row):
    ok = [e for e in entries if row in e["rows"] and not e["rows"][row].get("failed")]
    # Against physreg's own at-rest figure of the same targets (the same interpolation and file rounding).
    vs_rest = [e["rows"][row]["tre_mm"] / e["rows"][row]["methods"]["at_rest"]["tre_mm"] for e in ok]
    vs_peer = [e["rows"][row]["tre_mm"] / e["peer"]["tre_mm"] for e in ok if "tre_mm" in e.get("peer", {})]
    out = {"frames": len(ok), "failed": sum(1 for e in entries if e["rows"].get(row, {}).get("failed")),
           "tre_over_rest": ratio_stats(vs_rest), "tre_over_peer": ratio_stats(vs_peer),
           "worse_than_rest": sum(1 for x in vs_rest if x > 1.0 + 1e-6),
           "median_tre_mm": statistics.median([e["rows"][row]["tre_mm"] for e in ok]) if ok else None,
           "median_seconds": statistics.median([e["rows"][row]["seconds"] for e in ok]) if ok else None,
           "answers": {m: sum(1 for e in ok if e["rows"][row]["answer"] == m) for m in sorted({e["rows"][row]["answer"] for e in ok})}}
    pairs = [(e["rows"][row]["precision_mm"], e["rows"][row]["tre_mm"]) for e in ok if e["rows"][row].get("precision_mm") is not None]
    out["precision_vs_tre_spearman"] = spearman([p for p, _ in pairs], [t for _, t in pairs])
    return out


def write_docs(results, a):
    rows = [r for r in ROWS if any(r in e["rows"] for e in results)]
    # The linear sequences were generated by the peer's own model (its mesh, stiffness matrix and
    # Dirichlet nodes: its figures there are an inverse crime); the Neo-Hookean ones by another law.
    groups = {"all": results, "neohookean": [e for e in results if e["sequence"].startswith("neohookean")],
              "linear": [e for e in results if e["sequence"].startswith("linear")]}
    summary = {"rows": {row: row_stats(results, row) for row in rows},
               "by_generator": {g: {row: row_stats(entries, row) for row in rows} for g, entries in groups.items() if g != "all"}}
    summary["peer"] = {}
    for g, entries in groups.items():
        peer = [e for e in entries if "tre_mm" in e.get("peer", {})]
        summary["peer"][g] = {"median_tre_mm": statistics.median([e["peer"]["tre_mm"] for e in peer]) if peer else None,
                              "tre_over_rest": ratio_stats([e["peer"]["tre_mm"] / e["at_rest_mm"] for e in peer])}
    os.makedirs(os.path.join(ROOT, "docs", "results"), exist_ok=True)
    json.dump({"summary": summary, "frames": results, "command": " ".join(sys.argv)}, open(os.path.join(ROOT, "docs", "results", "adjoint_liver.json"), "w"), indent=1)
    md = ["# adjoint-liver: physreg register-surface beside the peer (Mestdagh & Cotin 2022)", "",
          "Mean error over the 604 interior nodes, mm; in brackets the answer written. `scripts/study_adjoint_liver.py`, "
          + time.strftime("%Y-%m-%d") + ". The peer is told the Dirichlet nodes and the force patch; on the linear sequences its "
          "model is the data's generator (same mesh, stiffness matrix and supports).", "",
          "| frame | at rest | peer | " + " | ".join(rows) + " |", "|---|---|---|" + "---|" * len(rows)]
    for e in results:
        cells = []
        for row in rows:
            r = e["rows"].get(row)
            cells.append("failed" if not r or r.get("failed") else f"{r['tre_mm']:.2f} ({r['answer']})")
        md.append(f"| {e['sequence']} f{e['frame']} | {e['at_rest_mm']:.2f} | {e.get('peer', {}).get('tre_mm', float('nan')):.2f} | " + " | ".join(cells) + " |")
    fmt = lambda x: "—" if x is None else f"{x:.2f}"
    for g in ("all", "neohookean", "linear"):
        stats = summary["rows"] if g == "all" else summary["by_generator"][g]
        md += ["", f"**{g} frames**", "", "| row | frames | median TRE / at rest | max TRE / at rest | worse than at rest | median TRE / peer | "
               "max TRE / peer | median s per run | halves precision vs TRE (Spearman) |", "|---|---|---|---|---|---|---|---|---|"]
        for row, s in stats.items():
            r, p = s["tre_over_rest"], s["tre_over_peer"]
            md.append(f"| {row} | {s['frames']} | {fmt(r['median'])} | {fmt(r['max'])} | {s['worse_than_rest']} | {fmt(p['median'])} | {fmt(p['max'])} | "
                      f"{fmt(s['median_seconds'])} | {fmt(s['precision_vs_tre_spearman'])} |")
        pr = summary["peer"][g]["tre_over_rest"]
        if pr["n"]:
            md.append(f"| peer | {pr['n']} | {pr['median']:.2f} | {pr['max']:.2f} | — | 1 | 1 | — | — |")
    open(os.path.join(ROOT, "docs", "results", "adjoint_liver.md"), "w").write("\n".join(md) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no figure", file=sys.stderr)
        return
    fig, ax = plt.subplots(figsize=(max(10, 0.3 * len(results) + 2), 4.6))
    x = np.arange(len(results))
    width = 0.8 / (len(rows) + 2)
    ax.bar(x - width * (len(rows) + 1) / 2, [e["at_rest_mm"] for e in results], width, label="at rest", color="0.75")
    ax.bar(x - width * (len(rows) - 1) / 2, [e.get("peer", {}).get("tre_mm", np.nan) for e in results], width, label="peer (Dirichlet + force patch)", color="k")
    for j, row in enumerate(rows):
        vals = [e["rows"][row]["tre_mm"] if row in e["rows"] and not e["rows"][row].get("failed") else np.nan for e in results]
        ax.bar(x - width * (len(rows) - 1) / 2 + width * (j + 1), vals, width, label="physreg " + row)
    ax.set_xticks(x)
    ax.set_xticklabels([f"{e['sequence'].replace('neohookean', 'nh').replace('linear', 'lin')}\nf{e['frame']}" for e in results], fontsize=6)
    ax.set_ylabel("mean interior-node error (mm)")
    ax.set_yscale("log")
    ax.legend(fontsize=7, ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False)
    ax.set_title("adjoint-liver (Mestdagh & Cotin 2022): physreg register-surface beside the peer")
    fig.tight_layout()
    os.makedirs(os.path.join(ROOT, "docs", "figures"), exist_ok=True)
    fig.savefig(os.path.join(ROOT, "docs", "figures", "adjoint_liver.png"), dpi=130)


if __name__ == "__main__":
    main()
