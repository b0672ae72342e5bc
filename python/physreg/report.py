# SPDX-License-Identifier: GPL-3.0-or-later
"""report.html: a self-contained page about one physreg run, made with matplotlib.

    python3 -m physreg.report OUTPUT_FOLDER [--output report.html]

Reads the folder's summary.json (register-compression, register-surface, register-images, demo)
and the files next to it, and writes one HTML file with inline PNG figures: inputs and parameters,
TRE table with bars, per-landmark errors, slices with label contours before/after and landmarks,
the displacement magnitude with a colour bar, convergence, timings. Written to a temporary name and
renamed. Exit status 1 with a message when the folder has no usable summary.
"""
import argparse
import base64
import html
import io
import json
import math
import os
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

TYPE_COLOURS = {"surface": "#2ca02c", "tumour": "#d62728", "vessel": "#1f77b4", "parenchyma": "#7f7f7f"}
METHOD_ORDER = ["at_rest", "rigid", "icp", "rigid_intensity", "rigid_labels", "demons_intensity", "demons_labels",
                "bspline_intensity", "bspline_labels", "biomechanical"]


class ReportError(Exception):
    pass


# ---- small HTML helpers ------------------------------------------------------------------------

def esc(value):
    return html.escape(str(value))


def figure_html(fig, caption):
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    data = base64.b64encode(buffer.getvalue()).decode("ascii")
    return f'<figure><img alt="{esc(caption)}" src="data:image/png;base64,{data}"><figcaption>{esc(caption)}</figcaption></figure>'


def fmt_value(v):
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def key_value_table(title, mapping):
    rows = []
    for key, value in mapping.items():
        if isinstance(value, dict):
            if all(not isinstance(v, (dict, list)) for v in value.values()) and len(value) <= 8:
                value = ", ".join(f"{k}: {fmt_value(v)}" for k, v in value.items())
            else:
                continue
        elif isinstance(value, list):
            if len(value) > 8 or any(isinstance(v, (dict, list)) for v in value):
                continue
            value = ", ".join(fmt_value(v) for v in value)
        rows.append(f"<tr><th>{esc(key)}</th><td>{esc(fmt_value(value))}</td></tr>")
    if not rows:
        return ""
    return f"<h3>{esc(title)}</h3><table class='kv'>{''.join(rows)}</table>"


def bar_cell(value, largest, unit="mm"):
    if value is None or not math.isfinite(value):
        return "<td>–</td>"
    width = 0 if largest <= 0 else max(1, int(120 * value / largest))
    return f"<td class='num'><span class='bar' style='width:{width}px'></span>{value:.3f} {unit}</td>"


# ---- data helpers ----------------------------------------------------------------------------

def read_landmark_csv(path):
    """name → (position, type) from physreg's CSV (name,x,y,z[,type])."""
    import physreg
    names, positions, types = physreg.read_landmarks(path)
    return {n: (positions[i], types[i]) for i, n in enumerate(names)}


def physical_axes(geometry):
    """Per image axis i, j, k: coordinate arrays (mm) of voxel centres, assuming an axis-aligned direction."""
    d = np.asarray(geometry.direction)
    if not np.allclose(np.abs(d), np.eye(3), atol=1e-6):
        return None
    return [geometry.origin[a] + d[a, a] * geometry.spacing[a] * np.arange(geometry.size[a]) for a in range(3)]


def slice_index(geometry, axis, coordinate):
    axes = physical_axes(geometry)
    if axes is None:
        return None
    k = int(round((coordinate - axes[axis][0]) / (axes[axis][1] - axes[axis][0]))) if len(axes[axis]) > 1 else 0
    return k if 0 <= k < geometry.size[axis] else None


def label_slice(array, geometry, z_mm):
    """The axial (constant z) slice through z_mm: (2-D array [y, x], x coords, y coords) or None."""
    k = slice_index(geometry, 2, z_mm)
    if k is None:
        return None
    axes = physical_axes(geometry)
    return array[k], axes[0], axes[1]


# ---- sections ----------------------------------------------------------------------------------

def methods_table(summary):
    """Rows: (method, tre dict or None, extra dict) for every method the summary reports."""
    rows = []
    methods = summary.get("methods")
    if isinstance(methods, dict):
        names = sorted(methods, key=lambda m: (METHOD_ORDER.index(m) if m in METHOD_ORDER else 99, m))
        for name in names:
            m = methods[name]
            if m.get("status") == "failed":  # a baseline that failed: said, not hidden
                rows.append((f"{name} — failed: {m.get('reason', '')}", None, {}))
                continue
            extra = {"seconds": m.get("seconds")}
            if "hausdorff_mm" in m:
                extra["hausdorff_mean_mm"] = m["hausdorff_mm"].get("mean")
                extra["hausdorff_max_mm"] = m["hausdorff_mm"].get("max")
            if isinstance(m.get("dice"), dict) and m["dice"]:
                extra["dice_mean"] = float(np.mean(list(m["dice"].values())))
            rows.append((name, m.get("tre"), extra))
    elif isinstance(methods, list):  # the demo: held-out and training TRE per method
        for m in methods:
            rows.append((m["method"] + " — held-out D, E", m.get("tre_held_out"), {"ms_per_update": m.get("ms_per_update")}))
            rows.append((m["method"] + " — training A, B, C", m.get("tre_training"), {}))
    elif "tre_against_dataset" in summary:
        rows.append((summary.get("model", {}).get("variant", "model"), summary["tre_against_dataset"], {"seconds": summary.get("seconds")}))
    return rows


def stat(tre, group, key="mean_mm"):
    if not tre or group not in tre or not isinstance(tre[group], dict):
        return None
    return tre[group].get(key)


def accuracy_section(summary):
    rows = methods_table(summary)
    if not rows:
        return ""
    largest = max([stat(t, g) or 0 for _, t, _ in rows for g in ("all", "surface", "internal")] + [0])
    has_h = any("hausdorff_mean_mm" in e for _, _, e in rows)
    has_dice = any("dice_mean" in e for _, _, e in rows)
    head = "<tr><th>method</th><th>TRE all (mean)</th><th>surface</th><th>internal</th><th>max</th>"
    head += "<th>Hausdorff mean / max</th>" if has_h else ""
    head += "<th>mean Dice</th>" if has_dice else ""
    head += "<th>time</th></tr>"
    body = []
    for name, tre, extra in rows:
        cells = f"<td>{esc(name)}</td>" + "".join(bar_cell(stat(tre, g), largest) for g in ("all", "surface", "internal"))
        mx = stat(tre, "all", "max_mm")
        cells += f"<td class='num'>{'–' if mx is None else f'{mx:.3f} mm'}</td>"
        if has_h:
            hm, hx = extra.get("hausdorff_mean_mm"), extra.get("hausdorff_max_mm")
            cells += f"<td class='num'>{'–' if hm is None else f'{hm:.2f} / {hx:.2f} mm'}</td>"
        if has_dice:
            d = extra.get("dice_mean")
            cells += f"<td class='num'>{'–' if d is None else f'{d:.3f}'}</td>"
        if extra.get("ms_per_update") is not None:
            cells += f"<td class='num'>{extra['ms_per_update']:.3g} ms/update</td>"
        elif extra.get("seconds") is not None:
            cells += f"<td class='num'>{extra['seconds']:.2f} s</td>"
        else:
            cells += "<td>–</td>"
        body.append(f"<tr>{cells}</tr>")
    out = f"<h2>Accuracy</h2><p>Target registration error (TRE) at the landmarks, mm; bars scale with the value.</p><table>{head}{''.join(body)}</table>"
    # Grouped bars.
    usable = [(n, t) for n, t, _ in rows if t]
    if usable:
        fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(usable) + 2), 3.4), layout="constrained")
        x = np.arange(len(usable))
        for i, (group, colour) in enumerate((("all", "#555555"), ("surface", TYPE_COLOURS["surface"]), ("internal", "#9467bd"))):
            values = [stat(t, group) or 0.0 for _, t in usable]
            ax.bar(x + (i - 1) * 0.27, values, 0.27, color=colour, label=group)
        ax.set_xticks(x, [n for n, _ in usable], rotation=25, ha="right", fontsize=8)
        ax.set_ylabel("mean TRE (mm)")
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
        out += figure_html(fig, "Mean TRE per method: all landmarks, surface landmarks, internal (tumour and vessel) landmarks")
    return out


def read_ground_truth_moduli(path):
    """Young's moduli (Pa) by tissue name from a phantom's ground_truth_tissues.yaml, or None."""
    try:
        import yaml  # Debian python3-yaml
        table = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
        return {t["name"]: float(t["young_modulus_pa"]) for t in table["tissues"]}
    except (OSError, ImportError, KeyError, TypeError, ValueError, AttributeError):
        return None
    except Exception as e:  # yaml.YAMLError: the report says so instead of failing
        return {"error": str(e)}


def parameters_vs_truth_section(summary, folder):
    """The demo's estimated (or literature) model parameters beside the phantom's drawn values.
    Only the report reads the ground truth: the registration never sees it."""
    fitted = summary.get("fitted")
    if not isinstance(fitted, dict) or not isinstance(fitted.get("young_modulus_pa"), dict):
        return ""
    truth = read_ground_truth_moduli(Path(folder) / "phantom" / "ground_truth_tissues.yaml")
    if truth is None:
        return ""
    if "error" in truth:
        return f"<h2>Parameters and the ground truth</h2><p>ground_truth_tissues.yaml could not be read: {esc(truth['error'])}</p>"
    model = fitted["young_modulus_pa"]
    free = set(summary.get("fit_identifiability", {}) or {})
    at_bound = set(summary.get("fit_at_bound", []) or [])
    ident = summary.get("fit_identifiability", {}) or {}

    start = summary.get("fit_start") if isinstance(summary.get("fit_start"), dict) else {}

    def start_value(key):
        value = start.get(key)
        if value is None:
            value = (start.get("young_modulus_pa") or {}).get(key)
        return value if isinstance(value, (int, float)) else None

    def status(key, model_key=None):
        if key not in free:
            return "fixed (literature)"
        begun, now = start_value(model_key or key), (model.get(model_key) if model_key else fitted.get(key))
        if begun and now and abs(math.log10(now / begun)) < 0.005:
            return "at start, not moved by the data"
        s = "estimated"
        if key in at_bound:
            s += ", AT A BOUND"
        if isinstance(ident.get(key), dict) and not ident[key].get("identifiable", True):
            s += ", not identifiable"
        return s

    rows = []
    # (row, model key, truth tissue, estimation key)
    for row, key, tissue, est in (("gel body E (Pa)", "body", "body", "body_young_pa"),
                                  ("parenchyma E (Pa)", "parenchyma", "parenchyma", None),
                                  ("tumour E (Pa)", "tumour", "lesion", "tumour_young_pa"),
                                  ("vessel E (Pa)", "vessel", "vessel", "vessel_young_pa")):
        if key in model and tissue in truth:
            rows.append((row, model[key], truth[tissue], status(est, key) if est else "fixed (literature)"))
    if "parenchyma" in model and "parenchyma" in truth:
        # Under displacement loading only the ratios are observable.
        for row, key, tissue in (("gel / parenchyma", "body", "body"), ("tumour / parenchyma", "tumour", "lesion"),
                                 ("vessel / parenchyma", "vessel", "vessel")):
            if key in model and tissue in truth:
                rows.append((row, model[key] / model["parenchyma"], truth[tissue] / truth["parenchyma"], "ratio"))
    for row, key in (("k_c,s-t (N/m)", "k_c_s_t_n_per_m"), ("k_c,s-v (N/m)", "k_c_s_v_n_per_m")):
        if key in fitted:
            rows.append((row, fitted[key], None, status(key)))
    body = []
    for row, value, drawn, how in rows:
        factor = f"{value / drawn:.2f}×" if drawn else "–"
        drawn_text = fmt_value(drawn) if drawn is not None else "no counterpart (the truth's organs are bonded)"
        body.append(f"<tr><th>{esc(row)}</th><td>{esc(fmt_value(value))}</td><td>{esc(drawn_text)}</td><td>{esc(factor)}</td><td>{esc(how)}</td></tr>")
    return ("<h2>Parameters and the ground truth</h2><p>The model's parameters (estimated on training compressions A, B, C, "
            "or literature values) beside the values the phantom drew for its ground truth (phantom/ground_truth_tissues.yaml; "
            "Mooney–Rivlin tetrahedra, a different model). Only this report reads them.</p>"
            "<table><tr><th>parameter</th><th>model</th><th>ground truth</th><th>model / truth</th><th>how set</th></tr>"
            + "".join(body) + "</table>")


def safeguard_section(summary):
    """register-surface: what each result can be judged by without the truth, and whether the data
    decide between them (issue 32)."""
    methods = summary.get("methods")
    determinacy = summary.get("determinacy")
    if not isinstance(methods, dict) or not isinstance(determinacy, dict):
        return ""
    out = "<h2>Safeguard: what the data decide</h2>"
    statement = esc(determinacy.get("statement", ""))
    if determinacy.get("pose_determined") is False:
        notes = "".join(f"<li>{esc(n)}</li>" for n in determinacy.get("notes", []))
        out += f"<p style='color:#a00'><b>{statement}</b></p><ul>{notes}</ul>"
    else:
        out += f"<p>{statement}.</p>"
    guard = summary.get("safeguard")
    if isinstance(guard, dict):
        flags = guard.get("flags") or []
        if flags:
            out += (f"<p style='color:#a00'><b>Flagged: the answer written is {esc(guard.get('answer', '?'))}, "
                    f"not {esc(guard.get('requested', '?'))}</b> (safeguard {esc(guard.get('setting', '?'))}).</p>"
                    + "<ul>" + "".join(f"<li>{esc(f)}</li>" for f in flags) + "</ul>"
                    if guard.get("answer") != guard.get("requested") else
                    f"<p style='color:#a00'><b>Flagged, kept as asked:</b> {esc(guard.get('statement', ''))}</p>")
        else:
            out += f"<p>{esc(guard.get('statement', ''))}.</p>"
    halves = summary.get("uncertainty")
    if isinstance(halves, dict) and halves.get("run"):
        # Issue 46 item 5: the cloud's two halves registered apart; their spread is twice the answer's standard error.
        colour = "" if halves.get("resolved") else " style='color:#a00'"
        out += (f"<p{colour}>Uncertainty (the cloud's random halves): {esc(halves.get('statement', ''))}"
                + (f"; at the targets, precision {halves['targets_precision_mean_mm']:.2f} mm (mean)" if halves.get("targets_precision_mean_mm") is not None else "")
                + f". Rule: {esc(halves.get('rule', ''))}.</p>")
    elif isinstance(halves, dict):
        out += f"<p>Uncertainty: {esc(halves.get('statement', ''))}.</p>"
    predicted = summary.get("predicted_error")
    if isinstance(predicted, dict):
        # Issue 56 item 6: the error the answer's strain energy predicts, calibrated on public data.
        out += f"<p>Predicted error: {esc(predicted.get('statement', ''))}" + (f". Rule: {esc(predicted['rule'])}" if predicted.get("rule") else "") + ".</p>"
    truth = summary.get("truth", {}).get("implied_rigid_motion") if isinstance(summary.get("truth"), dict) else None
    head = "<tr><th>method</th><th>cloud → model mean</th><th>strain energy</th><th>largest displacement</th><th>implied rotation</th><th>rigid start</th></tr>"
    body = []
    for name in sorted(methods, key=lambda m: (METHOD_ORDER.index(m) if m in METHOD_ORDER else 99, m)):
        m = methods[name]
        fit = (m.get("cloud_to_model_mm") or {}).get("mean")
        energy = m.get("strain_energy_mj")
        largest = m.get("largest_displacement_mm")
        rotation = (m.get("implied_rigid_motion") or {}).get("rotation_deg")
        cells = [esc(name), "–" if fit is None else f"{fit:.2f} mm", "–" if energy is None else f"{energy:.3g} mJ",
                 "–" if largest is None else f"{largest:.1f} mm", "–" if rotation is None else f"{rotation:.1f}°", esc(m.get("start", "–"))]
        body.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    out += f"<table>{head}{''.join(body)}</table>"
    if truth:
        out += f"<p>The ground truth implies a rotation of {truth['rotation_deg']:.1f}° (for judging the baselines; no method reads it).</p>"
    supports = summary.get("supports")
    if isinstance(supports, dict):
        out += (f"<p>Supports: {len(supports.get('nodes', []))} nodes, {esc(supports.get('kind', '?'))}"
                + (f" ({supports.get('stiffness_n_per_mm')} N/mm)" if supports.get("kind") == "elastic" else "")
                + "; from " + esc(", ".join(str(s.get("source")) for s in supports.get("sources", [])) or "none") + ".</p>")
    decision = summary.get("support_hypotheses")
    if isinstance(decision, dict) and decision.get("hypotheses"):
        # Issue 46 item 3: each way of holding the organ that was tried, and why the winner won.
        out += f"<p>{esc(decision.get('statement', ''))}. Rule: {esc(decision.get('rule', ''))}.</p>"
        head = ("<tr><th>supports</th><th>nodes</th><th>kind</th><th>cloud → model mean</th><th>strain energy</th>"
                "<th>apart from the answer</th><th>completed</th><th>chosen</th></tr>")
        rows = []
        for h in decision["hypotheses"]:
            fit = (h.get("cloud_to_model_mm") or {}).get("mean")
            apart = h.get("apart_from_chosen_mm")
            cells = [esc(h.get("name", "?")), str(h.get("nodes", "–")), esc(h.get("kind", "?")),
                     "–" if fit is None else f"{fit:.2f} mm", "–" if h.get("strain_energy_mj") is None else f"{h['strain_energy_mj']:.3g} mJ",
                     "–" if apart is None else f"{apart:.1f} mm", "yes" if h.get("completed") else esc(str(h.get("stopped"))),
                     "<b>yes</b>" if h.get("chosen") else ""]
            rows.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
        out += f"<table>{head}{''.join(rows)}</table>"
    notes = summary.get("notes")
    if isinstance(notes, list) and notes:
        out += "<p style='color:#a00'><b>Notes</b></p><ul>" + "".join(f"<li>{esc(str(n))}</li>" for n in notes) + "</ul>"
    return out


def per_landmark_errors(summary, folder):
    """{method: {name: (error_mm, type)}}."""
    result = {}
    methods = summary.get("methods")
    if isinstance(methods, dict):
        for name, m in methods.items():
            tre = m.get("tre", {})
            if isinstance(m.get("tre_per_landmark"), list):
                result[name] = {r["name"]: (r["error_mm"], r.get("type", "")) for r in m["tre_per_landmark"]}
            elif isinstance(tre.get("per_landmark_mm"), dict):
                result[name] = {k: (v, "") for k, v in tre["per_landmark_mm"].items()}
    dataset, state = dataset_of(summary)
    if not result and dataset and state and isinstance(summary.get("methods"), list):  # the demo: held-out state's CSVs
        truth = read_landmark_csv(dataset / "states" / state / "landmarks.csv")
        rest = read_landmark_csv(dataset / "rest" / "landmarks.csv")
        result["at_rest"] = {n: (float(np.linalg.norm(rest[n][0] - t[0])), t[1]) for n, t in truth.items() if n in rest}
        for csv in sorted((folder / "registration").glob(f"{state}_landmarks_*.csv")):
            predicted = read_landmark_csv(csv)
            method = csv.stem[len(f"{state}_landmarks_"):]
            result[method] = {n: (float(np.linalg.norm(predicted[n][0] - t[0])), t[1]) for n, t in truth.items() if n in predicted}
    elif not result and dataset and state and (folder / "landmarks.csv").exists():
        truth = read_landmark_csv(dataset / "states" / state / "landmarks.csv")
        predicted = read_landmark_csv(folder / "landmarks.csv")
        rest = read_landmark_csv(dataset / "rest" / "landmarks.csv")
        result["at_rest"] = {n: (float(np.linalg.norm(rest[n][0] - t[0])), t[1]) for n, t in truth.items() if n in rest}
        result["registered"] = {n: (float(np.linalg.norm(predicted[n][0] - t[0])), t[1]) for n, t in truth.items() if n in predicted}
    if dataset:  # types from the dataset where the summary lacks them
        try:
            types = {n: t for n, (_, t) in read_landmark_csv(dataset / "rest" / "landmarks.csv").items()}
            for errors in result.values():
                for n, (e, t) in list(errors.items()):
                    if not t and n in types:
                        errors[n] = (e, types[n])
        except Exception:  # the dataset may have moved; the types are cosmetic
            pass
    return result


def per_landmark_section(summary, folder):
    errors = per_landmark_errors(summary, folder)
    if not errors:
        return ""
    preferred = [summary.get("method"), "registered", "coarse_to_fine"]
    chosen = next((m for m in preferred if m in errors), next(iter(errors)))
    names = list(errors[chosen])
    fig, ax = plt.subplots(figsize=(max(7, 0.32 * len(names) + 2), 3.6), layout="constrained")
    x = np.arange(len(names))
    if "at_rest" in errors and chosen != "at_rest":
        ax.bar(x - 0.2, [errors["at_rest"].get(n, (0, ""))[0] for n in names], 0.4, color="#cccccc", label="at rest")
    ax.bar(x + 0.2, [errors[chosen][n][0] for n in names], 0.4,
           color=[TYPE_COLOURS.get(errors[chosen][n][1], "#777777") for n in names], label=chosen)
    ax.set_xticks(x, names, rotation=90, fontsize=6)
    ax.set_ylabel("TRE (mm)")
    ax.grid(axis="y", alpha=0.3)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in TYPE_COLOURS.values()]
    ax.legend(handles + ([plt.Rectangle((0, 0), 1, 1, color="#cccccc")] if "at_rest" in errors else []),
              list(TYPE_COLOURS) + (["at rest"] if "at_rest" in errors else []), fontsize=7, ncol=4)
    rows = "".join(f"<tr><td>{esc(n)}</td><td>{esc(errors[chosen][n][1])}</td>" +
                   "".join(f"<td class='num'>{errors[m][n][0]:.3f}</td>" if n in errors[m] else "<td>–</td>" for m in errors) + "</tr>"
                   for n in names)
    head = "<tr><th>landmark</th><th>type</th>" + "".join(f"<th>{esc(m)}</th>" for m in errors) + "</tr>"
    return (f"<h2>Per-landmark errors</h2>" + figure_html(fig, f"TRE per landmark, {chosen} (colour: landmark type) beside the landmarks left at rest")
            + f"<details><summary>Table (mm)</summary><table>{head}{rows}</table></details>")


def convergence_section(summary):
    methods = summary.get("methods") if isinstance(summary.get("methods"), dict) else {}
    bio = methods.get("biomechanical", {})
    figs = ""
    if isinstance(bio.get("history"), list) and bio["history"]:
        h = bio["history"]
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.2), layout="constrained")
        cycles = [r["cycle"] for r in h]
        ax[0].semilogy(cycles, [r["objective_mm2"] for r in h], "o-")
        ax[0].set_xlabel("alternation cycle")
        ax[0].set_ylabel("objective Φ (mm²)")
        ax[1].plot(cycles, [r["rms_distance_mm"] for r in h], "o-", color="#d62728")
        ax[1].set_xlabel("alternation cycle")
        ax[1].set_ylabel("rms surface distance (mm)")
        for a in ax:
            a.grid(alpha=0.3)
        figs += figure_html(fig, "Convergence of the biomechanical registration (boundary load / moduli alternation)")
    if isinstance(bio.get("plateaus"), list) and bio["plateaus"]:
        p = bio["plateaus"]
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.2), layout="constrained")
        ax[0].plot([r["plateau"] for r in p], [r["mean_pair_distance_mm"] for r in p], "o-")
        ax[0].set_xlabel("annealing plateau")
        ax[0].set_ylabel("mean pair distance (mm)")
        ax[1].bar([r["plateau"] for r in p], [r["pairs"] for r in p], color="#1f77b4")
        ax[1].set_xlabel("annealing plateau")
        ax[1].set_ylabel("matched pairs kept")
        for a in ax:
            a.grid(alpha=0.3)
        figs += figure_html(fig, "Convergence of the surface registration: pair distances and pairs per annealing plateau")
    return f"<h2>Convergence</h2>{figs}" if figs else ""


def moduli_section(summary, folder):
    """register-images: each structure's Young's modulus, and whether the data determine it."""
    path = Path(folder) / "parameters.json"
    if summary.get("command") != "register-images" or not path.exists():
        return ""
    try:
        structures = json.loads(path.read_text(encoding="utf-8")).get("structures", [])
    except json.JSONDecodeError as e:
        raise ReportError(f"{path}: not valid JSON ({e})")
    rows = ""
    for s in structures:
        sens = s.get("sensitivity")
        if sens:
            change = max(sens["boundary_change_mm"]["modulus_doubled"], sens["boundary_change_mm"]["modulus_halved"])
            verdict = (f"yes: ×2 or ×½ moves its boundary {change:.3f} mm rms (voxel {sens['voxel_mm']:.2f} mm)" if sens["determined_by_the_data"]
                       else f"<b>no</b>: ×2 or ×½ moves its boundary only {change:.3f} mm rms (voxel {sens['voxel_mm']:.2f} mm) — not a measurement")
        else:
            verdict = "held (reference of its piece, or estimation off)"
        rows += (f"<tr><td>{esc(s.get('label'))}</td><td>{esc(s.get('name', ''))}</td><td class='num'>{s['initial_young_modulus_pa']:.4g}</td>"
                 f"<td class='num'>{s['young_modulus_pa']:.4g}</td><td>{verdict}</td></tr>")
    if not rows:
        return ""
    return ("<h2>Young's moduli</h2><table><tr><th>label</th><th>tissue</th><th>initial (Pa)</th><th>final (Pa)</th>"
            "<th>determined by the segmentations?</th></tr>" + rows + "</table>")


def displacement_section(folder):
    path = folder / "displacement.nii.gz"
    if not path.exists():
        return ""
    import physreg
    u, g = physreg.read_displacement_field(path)
    magnitude = np.linalg.norm(u, axis=-1)
    if not np.isfinite(magnitude).all():
        raise ReportError(f"{path}: non-finite displacement")
    k, j, i = np.unravel_index(np.argmax(magnitude), magnitude.shape)
    axes = physical_axes(g)
    if axes is None:
        axes = [np.arange(g.size[a]) * g.spacing[a] for a in range(3)]
    vmax = float(magnitude.max()) or 1.0
    fig, ax = plt.subplots(1, 3, figsize=(11, 3.6), layout="constrained")
    views = [(magnitude[k], axes[0], axes[1], "x (mm)", "y (mm)", f"axial z = {axes[2][k]:.1f} mm"),
             (magnitude[:, j, :], axes[0], axes[2], "x (mm)", "z (mm)", f"coronal y = {axes[1][j]:.1f} mm"),
             (magnitude[:, :, i], axes[1], axes[2], "y (mm)", "z (mm)", f"sagittal x = {axes[0][i]:.1f} mm")]
    for a, (img, h, v, xl, yl, title) in zip(ax, views):
        im = a.imshow(img, origin="lower", extent=(h[0], h[-1], v[0], v[-1]), cmap="viridis", vmin=0, vmax=vmax, aspect="equal")
        a.set_xlabel(xl)
        a.set_ylabel(yl)
        a.set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax, shrink=0.85, label="|u| (mm)")
    return ("<h2>Displacement</h2>" + figure_html(fig, f"Displacement magnitude (largest {vmax:.2f} mm) on three slices through its maximum, "
                                                      f"{path.name} ({g.size[0]}×{g.size[1]}×{g.size[2]} voxels)"))


def dataset_of(summary):
    inputs = summary.get("inputs", {}) if isinstance(summary.get("inputs"), dict) else {}
    dataset = inputs.get("dataset") or summary.get("dataset")
    state = inputs.get("state") or inputs.get("pictured_state") or summary.get("state")
    return (Path(dataset) if dataset and Path(dataset).exists() else None), state


def slices_section(summary, folder):
    """The deformed state's image with label contours before (rest) and after (truth or warped), and landmarks."""
    import physreg
    dataset, state = dataset_of(summary)
    inputs = summary.get("inputs", {}) if isinstance(summary.get("inputs"), dict) else {}
    if dataset and state:
        background = dataset / "states" / state / "intensity.nii.gz"
        truth_labels = dataset / "states" / state / "labels.nii.gz"
        before_labels = dataset / "rest" / "labels.nii.gz"
        truth_landmarks = dataset / "states" / state / "landmarks.csv"
        rest_landmarks = dataset / "rest" / "landmarks.csv"
    elif inputs.get("fixed") and inputs.get("fixed_labels") and inputs.get("moving_labels"):
        background, truth_labels, before_labels = Path(inputs["fixed"]), Path(inputs["fixed_labels"]), Path(inputs["moving_labels"])
        truth_landmarks = Path(inputs["landmarks_fixed"]) if inputs.get("landmarks_fixed") else None
        rest_landmarks = Path(inputs["landmarks_moving"]) if inputs.get("landmarks_moving") else None
    else:
        return ""
    if not (background.exists() and truth_labels.exists() and before_labels.exists()):
        return ""
    image, gi = physreg.read_image(background)
    truth, gt = physreg.read_labels(truth_labels)
    before, gb = physreg.read_labels(before_labels)
    after = None
    if (folder / "warped_labels.nii.gz").exists():
        after = physreg.read_labels(folder / "warped_labels.nii.gz")
    lm_truth = read_landmark_csv(truth_landmarks) if truth_landmarks and truth_landmarks.exists() else {}
    lm_rest = read_landmark_csv(rest_landmarks) if rest_landmarks and rest_landmarks.exists() else {}
    predicted_csv = folder / "landmarks.csv"
    if isinstance(summary.get("methods"), list) and state:  # the demo
        predicted_csv = folder / "registration" / f"{state}_landmarks_coarse_to_fine.csv"
    lm_pred = read_landmark_csv(predicted_csv) if predicted_csv.exists() else {}
    axes = physical_axes(gi)
    if axes is None:
        return "<h2>Slices</h2><p>Not drawn: the image's direction is not axis-aligned.</p>"
    # Slices through the internal landmarks (tumours and vessels), else through the labels' centre.
    internal = [p for p, t in lm_truth.values() if t in ("tumour", "vessel")]
    zs = sorted({float(p[2]) for p in internal})
    if not zs:
        kk = np.nonzero(truth.any(axis=(1, 2)))[0]
        zs = [float(axes[2][int(np.median(kk))])] if len(kk) else [float(axes[2][len(axes[2]) // 2])]
    picks = [zs[len(zs) // 4], zs[(3 * len(zs)) // 4]] if len(zs) > 1 else zs
    fig, axs = plt.subplots(1, len(picks), figsize=(5.2 * len(picks), 5), layout="constrained", squeeze=False)
    for a, z in zip(axs[0], picks):
        k = slice_index(gi, 2, z)
        if k is None:
            continue
        a.imshow(image[k], origin="lower", cmap="gray", extent=(axes[0][0], axes[0][-1], axes[1][0], axes[1][-1]))
        contours = [((before, gb), "dashed", "#ff7f0e", "before (moving/rest)"), ((truth, gt), "solid", "#2ca02c", "truth (fixed)")]
        if after is not None:
            contours.append((after, "solid", "#d62728", "after (warped)"))
        for (array, geometry), style, colour, label in contours:
            s = label_slice(array, geometry, z)
            if s is None or not s[0].any():
                continue
            for value in np.unique(s[0])[1:]:  # every structure's own outline
                a.contour(s[1], s[2], (s[0] == value).astype(float), levels=[0.5], colors=colour, linestyles=style, linewidths=0.9)
            a.plot([], [], color=colour, linestyle=style, label=label)
        near = [n for n, (p, _) in lm_truth.items() if abs(p[2] - z) <= 3.0 * gi.spacing[2]]
        for source, marker, colour, label in ((lm_rest, "x", "#ff7f0e", "landmark at rest"), (lm_truth, "o", "#2ca02c", "landmark truth"),
                                              (lm_pred, "+", "#d62728", "landmark predicted")):
            pts = np.array([source[n][0] for n in near if n in source])
            if len(pts):
                a.plot(pts[:, 0], pts[:, 1], marker, color=colour, markersize=6, mfc="none", linestyle="none", label=label)
        a.set_title(f"axial z = {z:.1f} mm", fontsize=9)
        a.set_xlabel("x (mm, LPS)")
        a.set_ylabel("y (mm, LPS)")
        a.legend(fontsize=6, loc="lower right")
    return "<h2>Slices</h2>" + figure_html(fig, "The deformed image with the organ contours before registration (dashed), the truth (green) and, "
                                                "where the command warps labels, after registration (red); landmarks within 3 slices")


def timing_section(summary):
    parts = {}
    seconds = summary.get("seconds")
    if isinstance(seconds, dict):
        parts = {k: v for k, v in seconds.items() if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "total"}
    methods = summary.get("methods") if isinstance(summary.get("methods"), dict) else {}
    split = methods.get("biomechanical", {}).get("time_split_s")
    if isinstance(split, dict):
        parts = {f"biomechanical: {k}": v for k, v in split.items()}
    total = seconds.get("total") if isinstance(seconds, dict) else seconds
    text = f"<p>Total run time: {total:.2f} s.</p>" if isinstance(total, (int, float)) else ""
    if not parts:
        return f"<h2>Timings</h2>{text}" if text else ""
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(parts) + 1.2), layout="constrained")
    ax.barh(list(parts), list(parts.values()), color="#8c564b")
    ax.set_xlabel("seconds")
    ax.invert_yaxis()
    ax.grid(axis="x", alpha=0.3)
    return f"<h2>Timings</h2>{text}" + figure_html(fig, "Where the time went (s)")


STYLE = """
body{font-family:system-ui,-apple-system,'DejaVu Sans',sans-serif;margin:2em auto;max-width:1100px;color:#222;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}th,td{border:1px solid #ddd;padding:.25em .6em;text-align:left}
th{background:#f4f4f4}td.num{text-align:right;white-space:nowrap}table.kv th{width:16em}
.bar{display:inline-block;height:.7em;background:#4c72b0;margin-right:.5em;vertical-align:middle}
figure{margin:1em 0}figure img{max-width:100%}figcaption{font-size:.85em;color:#555}.meta{color:#666;font-size:.9em}
"""


def build_report(folder, shown_as=None):
    """The HTML page for `folder`; `shown_as` is the folder's name on the page (the final name
    when the command writes into a staging folder)."""
    folder = Path(folder)
    summary_path = folder / "summary.json"
    if not summary_path.exists():
        raise ReportError(f"{summary_path}: file does not exist")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ReportError(f"{summary_path}: not valid JSON ({e})")
    import physreg
    command = summary.get("command") or ("demo" if isinstance(summary.get("methods"), list) else "register-compression")
    if command == "demo" and "inputs" not in summary and (folder / "phantom" / "manifest.json").exists():
        # The demo runs compressions A-E; its pictures show the held-out compression D.
        # The final folder's name, not the staging folder that the report is drawn in.
        dataset_folder = Path(shown_as) / "phantom" if shown_as else (folder / "phantom").resolve()
        summary = dict(summary, inputs={"dataset": str(dataset_folder), "states": "compressions A, B, C (training) and D, E (held out)",
                                        "pictured_state": "D", "preset": summary.get("preset"), "seed": summary.get("seed")})
    sections = [
        key_value_table("Inputs", summary.get("inputs", {}) if isinstance(summary.get("inputs"), dict) else {}),
        key_value_table("Parameters", summary.get("parameters", {}) if isinstance(summary.get("parameters"), dict) else {}),
        key_value_table("Model", summary.get("model", {}) if isinstance(summary.get("model"), dict) else {}),
        accuracy_section(summary),
        parameters_vs_truth_section(summary, folder) if command == "demo" else "",
        safeguard_section(summary),
        per_landmark_section(summary, folder),
        slices_section(summary, folder),
        displacement_section(folder),
        convergence_section(summary),
        moduli_section(summary, folder),
        timing_section(summary),
    ]
    units = summary.get("units")
    units_text = ", ".join(f"{k}: {v}" for k, v in units.items()) if isinstance(units, dict) else (units or "mm, LPS")
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>physreg {esc(command)} — {esc(Path(shown_as).name if shown_as else folder.name)}</title>"
            f"<style>{STYLE}</style></head><body><h1>physreg {esc(command)}</h1>"
            f"<p class='meta'>Folder {esc(shown_as or folder.resolve())} · physreg {esc(physreg.__version__)} · units: {esc(units_text)}</p>"
            + "".join(sections) + "</body></html>\n")


def write_report(folder, output=None, shown_as=None):
    folder = Path(folder)
    output = Path(output) if output else folder / "report.html"
    page = build_report(folder, shown_as)
    fd, tmp = tempfile.mkstemp(prefix=".report-", suffix=".html", dir=output.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(page)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; a report is an ordinary file
        os.replace(tmp, output)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return output


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python3 -m physreg.report", description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="a physreg output folder (with summary.json)")
    parser.add_argument("--output", help="the HTML file (default FOLDER/report.html)")
    parser.add_argument("--shown-as", help="the folder's name on the page (default: FOLDER)")
    args = parser.parse_args(argv)
    try:
        path = write_report(args.folder, args.output, args.shown_as)
    except (ReportError, OSError) as e:
        print(f"physreg report: error: {e}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
