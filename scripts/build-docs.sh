#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# `make docs`: Doxygen over include/ (XML; its warnings are errors), then Sphinx with warnings as
# errors into BUILD/docs/html. Needs the built program (the options' reference is generated from
# `physreg settings --json`) and the Python module (autodoc imports it).
set -euo pipefail
cd "$(dirname "$0")/.."
build=$(realpath "${1:-build}")
export PHYSREG_SOURCE_DIR=$PWD
export PHYSREG_BUILD_DIR=$build
export PHYSREG_DOXYGEN_DIR=$build/docs/doxygen
export PHYSREG_DOXYGEN_XML=$build/docs/doxygen/xml
export PHYSREG_PYTHON_DIR=$build/python
export PHYSREG_EXECUTABLE=$build/bin/physreg
mkdir -p "$PHYSREG_DOXYGEN_DIR"
started=$(date +%s)
doxygen docs/Doxyfile
if [ -s "$PHYSREG_DOXYGEN_DIR/warnings.log" ]; then
  echo "docs: Doxygen warnings ($PHYSREG_DOXYGEN_DIR/warnings.log):" >&2
  cat "$PHYSREG_DOXYGEN_DIR/warnings.log" >&2
  exit 1
fi
# -W --keep-going: every warning is listed, and any one fails the build. -E: no stale environment.
/usr/bin/python3 -m sphinx -b html -q -W --keep-going -E docs "$build/docs/html"
echo "docs: $build/docs/html/index.html ($(($(date +%s) - started)) s)"
