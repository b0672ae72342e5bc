#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# ctest fixture: the small phantom dataset that the CLI test, the bad-input catalogue and the MPI test
# read (never write), made once per ctest run instead of once per test. Its --json output is kept
# beside it for the CLI test's manifest checks.
#   make_phantom_fixture.sh PHYSREG OUTPUT_DIR
set -eu
physreg="$1"
out="$2"
rm -rf "$out" "$out.stdout.json"
mkdir -p "$(dirname "$out")"
"$physreg" --log-level warn phantom --preset small --seed 3 --depths 8,10,8,6 -o "$out" --json > "$out.stdout.json.tmp"
mv "$out.stdout.json.tmp" "$out.stdout.json"
echo "fixture: small phantom in $out"
