#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Installs the build tree into a temporary prefix, builds a downstream project against it with
# find_package(physreg CONFIG REQUIRED), runs it, runs the installed program, and imports the
# installed Python package. Usage: test_consumer.sh BUILD_DIR CONSUMER_SOURCE [PYTHON]
set -euo pipefail
build=$1 consumer=$2 python=${3:-}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
test -f "$work/prefix/lib/cmake/physreg/physregConfig.cmake"
test -f "$work/prefix/lib/cmake/physreg/physregConfigVersion.cmake"
test -f "$work/prefix/include/physreg/core/version.hpp"
cmake -S "$consumer" -B "$work/consumer" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/consumer" >/dev/null
"$work/consumer/consumer"
# The installed program runs from the prefix (its RPATH finds the installed library).
"$work/prefix/bin/physreg" --version
if [ -n "$python" ] && [ -d "$work/prefix/lib/python3/dist-packages/physreg" ]; then
  PYTHONPATH="$work/prefix/lib/python3/dist-packages" "$python" -c \
    "import physreg, numpy; g = physreg.ImageGeometry(spacing=(2, 2, 2)); print('python physreg', physreg.__version__, g)"
fi
# A version the install does not satisfy is refused at configure time.
cp -r "$consumer" "$work/too_new"
sed -i 's/find_package(physreg 0.1 CONFIG REQUIRED)/find_package(physreg 9.0 CONFIG REQUIRED)/' "$work/too_new/CMakeLists.txt"
if cmake -S "$work/too_new" -B "$work/too_new_build" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null 2>&1; then
  echo "FAIL: find_package(physreg 9.0) accepted version 0.1" >&2
  exit 1
fi
echo "consumer project OK"
