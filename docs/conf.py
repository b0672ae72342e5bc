# SPDX-License-Identifier: GPL-3.0-or-later
# The documentation site (issue 59): Sphinx 5.3 + myst-parser (these Markdown pages), breathe over
# Doxygen's XML (the C++ API from include/), autodoc (the Python package). Built by `make docs`
# (scripts/build-docs.sh), which runs Doxygen first and passes the paths below in the environment.
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.environ.get("PHYSREG_BUILD_DIR", os.path.join(ROOT, "build"))
sys.path.insert(0, os.environ.get("PHYSREG_PYTHON_DIR", os.path.join(BUILD, "python")))

project = "physreg"
author = "the physreg developers"
copyright = "2026, the physreg developers (GPL-3.0-or-later)"
release = "0.1.0"

extensions = ["myst_parser", "breathe", "sphinx.ext.autodoc"]
myst_heading_anchors = 4
source_suffix = {".md": "markdown"}
html_theme = "pydata_sphinx_theme"
html_title = "physreg"
html_theme_options = {"navigation_depth": 2}
breathe_projects = {"physreg": os.environ.get("PHYSREG_DOXYGEN_XML", os.path.join(BUILD, "docs", "doxygen", "xml"))}
breathe_default_project = "physreg"
autodoc_member_order = "bysource"
exclude_patterns = ["_build", "Doxyfile"]


def write_settings_reference(app):
    """reference/_generated/<mode>.md from `physreg settings MODE --json`: the options' page is the
    settings specification itself, so it cannot drift from the program."""
    program = os.environ.get("PHYSREG_EXECUTABLE", os.path.join(BUILD, "bin", "physreg"))
    out = os.path.join(app.srcdir, "reference", "_generated")
    os.makedirs(out, exist_ok=True)
    modes = ["register-surface", "register-images", "register-compression", "estimate", "enrich-build", "enrich-apply"]
    for mode in modes:
        spec = json.loads(subprocess.run([program, "settings", mode, "--json"], check=True, capture_output=True, text=True).stdout)
        lines = [f"# {mode}", "", f"Generated from `physreg settings {mode} --json` when the site was built. A settings file "
                 "(`--settings F`, YAML or JSON) holds the keys; the option on the command line wins over the file; Python's "
                 "functions take the keys as keyword arguments.", "",
                 "| key | option | default | allowed | meaning |", "|---|---|---|---|---|"]
        for s in spec_entries(spec):
            cell = lambda v: str(v).replace("|", "\\|").replace("\n", " ")
            lines.append(f"| `{s.get('key', '')}` | `{s.get('option', '')}` | {cell(default_text(s))} | {cell(allowed_text(s))} | {cell(s.get('help', ''))} |")
        text = "\n".join(lines) + "\n"
        path = os.path.join(out, mode + ".md")
        if not os.path.exists(path) or open(path).read() != text:
            open(path, "w").write(text)


def spec_entries(spec):
    entries = spec.get("settings", spec) if isinstance(spec, dict) else spec
    return entries if isinstance(entries, list) else [dict(v, key=k) for k, v in entries.items()]


def default_text(s):
    d = s.get("default")
    unit = s.get("unit") or ""
    return "" if d is None else (f"`{json.dumps(d)}`" + (f" {unit}" if unit else ""))


def allowed_text(s):
    if s.get("choices"):
        return " \\| ".join(f"`{c}`" for c in s["choices"])
    return s.get("range", "")


def setup(app):
    app.connect("builder-inited", write_settings_reference)
