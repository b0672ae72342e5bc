# SPDX-License-Identifier: GPL-3.0-or-later
"""report.html: written by the register-* commands, self-contained, loads in headless Chromium."""
import base64
import re
import shutil
import subprocess

import numpy as np
import pytest

import physreg
from conftest import skip_or_fail
from physreg import report


@pytest.fixture(scope="module")
def registered(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    physreg.register_images(out / "ri", dataset=dataset, cycles=2, cell_size=8, baselines="labels", quiet=True)
    physreg.register_compression(out / "rc", dataset=dataset, state="A", grid="12x10x6", quiet=True)
    return out


def images_of(page):
    return re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)


def test_register_images_writes_a_self_contained_report(registered):
    page = (registered / "ri" / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    # Nothing is fetched from elsewhere: every picture is inline.
    assert not re.search(r'(src|href)="(?!data:)', page)
    pictures = images_of(page)
    assert len(pictures) >= 5  # TRE bars, per-landmark bars, slices, displacement, convergence, timings
    for p in pictures:
        assert base64.b64decode(p)[:8] == b"\x89PNG\r\n\x1a\n"
    for method in ("at_rest", "biomechanical", "rigid_labels", "demons_labels", "bspline_labels"):
        assert f"<td>{method}</td>" in page
    for section in ("Accuracy", "Per-landmark errors", "Slices", "Displacement", "Convergence", "Timings"):
        assert f"<h2>{section}</h2>" in page
    # The page names the final folder, not the staging one the command wrote into.
    assert str((registered / "ri").resolve()) in page and ".partial" not in page


def test_register_compression_report_shows_the_summary_tre(registered):
    import json
    summary = json.loads((registered / "rc" / "summary.json").read_text())
    page = (registered / "rc" / "report.html").read_text()
    mean = summary["tre_against_dataset"]["all"]["mean_mm"]
    assert f"{mean:.3f} mm" in page
    assert "<h2>Per-landmark errors</h2>" in page


def test_no_report_flag_and_a_folder_without_summary(dataset, tmp_path):
    physreg.run("--no-report register-compression", dataset=dataset, state="A", grid="12x10x6", output=tmp_path / "rc", quiet=True)
    assert (tmp_path / "rc" / "summary.json").exists() and not (tmp_path / "rc" / "report.html").exists()
    (tmp_path / "empty").mkdir()
    assert report.main([str(tmp_path / "empty")]) == 1
    assert not (tmp_path / "empty" / "report.html").exists()
    (tmp_path / "empty" / "summary.json").write_text("{ not json")
    with pytest.raises(report.ReportError, match=r"not valid JSON"):
        report.build_report(tmp_path / "empty")


def chromium():
    return shutil.which("chromium") or shutil.which("chromium-browser")


def load_in_chromium(page, png):
    r = subprocess.run([chromium(), "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
                        "--v=0", "--window-size=1200,2400", f"--screenshot={png}", page.resolve().as_uri()],
                       capture_output=True, text=True, timeout=120)
    return r.returncode, [l for l in r.stderr.splitlines() if ":CONSOLE" in l]


def test_report_opens_in_chromium_without_console_errors(registered, tmp_path):
    if chromium() is None:
        skip_or_fail("Chromium is not installed (Debian package chromium): the page was not loaded in a browser")
    # The check can see console errors: a page that logs one is caught.
    control = tmp_path / "control.html"
    control.write_text('<!DOCTYPE html><html><body><script>console.error("control error")</script></body></html>')
    _, messages = load_in_chromium(control, tmp_path / "control.png")
    assert any("control error" in m for m in messages), "Chromium's console log is not visible to this test"
    for name in ("ri", "rc"):
        code, messages = load_in_chromium(registered / name / "report.html", tmp_path / f"{name}.png")
        assert code == 0 and messages == [], messages
        import matplotlib.image
        shot = matplotlib.image.imread(tmp_path / f"{name}.png")
        assert shot.shape[0] >= 2000 and shot.shape[1] >= 1100
        # Not blank: the text, tables and figures give a spread of grey levels.
        grey = shot[..., :3].mean(axis=2)
        assert grey.std() > 0.05 and (grey < 0.5).mean() > 0.01


def test_demo_report_sets_the_parameters_beside_the_ground_truth(tmp_path):
    # A demo folder as `physreg demo` leaves it: the summary's fitted parameters and the phantom's
    # drawn moduli (only the report reads those).
    import json
    (tmp_path / "phantom").mkdir()
    (tmp_path / "phantom" / "ground_truth_tissues.yaml").write_text(
        "tissues:\n"
        "  - {label: 2, name: parenchyma, young_modulus_pa: 250000.0, poisson_ratio: 0.495}\n"
        "  - {label: 3, name: lesion, young_modulus_pa: 5000000.0, poisson_ratio: 0.495}\n"
        "  - {label: 4, name: vessel, young_modulus_pa: 1000000.0, poisson_ratio: 0.495}\n"
        "  - {label: 1, name: body, young_modulus_pa: 25000.0, poisson_ratio: 0.497}\n")
    summary = {"preset": "small", "seed": 1, "methods": [],
               "fitted": {"k_c_s_t_n_per_m": 800.0, "k_c_s_v_n_per_m": 500.0, "region": "body", "variant": "coupled",
                          "young_modulus_pa": {"body": 1e5, "parenchyma": 2e5, "tumour": 5e6, "vessel": 1e6}},
               "fit_at_bound": ["body_young_pa"],
               "fit_identifiability": {"k_c_s_t_n_per_m": {"identifiable": False, "objective_change_mm_per_decade": 0.001},
                                       "k_c_s_v_n_per_m": {"identifiable": False, "objective_change_mm_per_decade": 0.001},
                                       "body_young_pa": {"identifiable": True, "objective_change_mm_per_decade": 0.2}}}
    page = report.parameters_vs_truth_section(json.loads(json.dumps(summary)), tmp_path)
    assert "<h2>Parameters and the ground truth</h2>" in page
    # gel/parenchyma: model 0.5, truth 0.1, so the model is 5× stiffer relative to the liver.
    row = re.search(r"<tr><th>gel / parenchyma</th><td>([^<]*)</td><td>([^<]*)</td><td>([^<]*)</td>", page)
    assert row and row.groups() == ("0.5", "0.1", "5.00×"), row and row.groups()
    assert re.search(r"<th>gel body E \(Pa\)</th>.*?estimated, AT A BOUND</td>", page)
    assert re.search(r"<th>k_c,s-t \(N/m\)</th><td>800</td>.*?estimated, not identifiable</td>", page)
    assert re.search(r"<th>parenchyma E \(Pa\)</th>.*?fixed \(literature\)</td>", page)
