#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# An enrichment database built by 2 MPI ranks (mpirun) is byte-identical to the 1-process build.
set -eu
physreg="$1"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The small phantom: ctest's shared fixture (tests/cli/make_phantom_fixture.sh, read only), or our own.
ph="${PHYSREG_TEST_PHANTOM:-}"
if [ -z "$ph" ] || [ ! -f "$ph/manifest.json" ]; then
  ph="$work/ph"
  "$physreg" --log-level warn phantom --preset small --depths 6,8,6,6 --no-calculix -o "$ph"
fi
# A small grid (3 sequences split unevenly over 2 ranks): the test is about the split and the gather,
# not the database; 3 s in Release, about 1 min under ASan (the 36x27x12 grid took 6 min there).
args=(--log-level warn enrich build --dataset "$ph" --grid 24x18x8 --coarse-grid 12x9x4 --positions B,C,D --depths 6,10)
"$physreg" "${args[@]}" -o "$work/one.phe"
root=()
[ "$(id -u)" -eq 0 ] && root=(--allow-run-as-root)
OMP_NUM_THREADS=1 mpirun "${root[@]}" --oversubscribe -np 2 "$physreg" "${args[@]}" -o "$work/two.phe"
cmp "$work/one.phe" "$work/two.phe"
[ ! -e "$work/two.phe.partial" ]
echo "mpi: 2-rank database identical to the 1-process build ($(stat -c %s "$work/one.phe") bytes)"
