#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Threads on a shared machine: bench_tled's explicit steps (74×18×54 block, double) and tangent
# assembly (24×18×18) on 1 and 2 threads, on a quiet machine and beside a competing CPU-bound
# process: the thread governor off with libgomp's default waiting (GOMP_SPINCOUNT=300000: the old
# behaviour), the governor with libgomp's default waiting, the governor with the short spin that
# the physreg program and bench_tled now set themselves (GOMP_SPINCOUNT=1000, core/openmp_wait.hpp:
# the default), and the governor with passive waiting. JSON per condition in
# bench/results/shared_load/. Each repetition runs ≥ MIN_TIME s (default 4) on one solver, so the
# governor's first decisions are a small part of it (MIN_TIME=0.5: a cold start).
# Run from the repository root after `make build`: bench/shared_load.sh [build/bin/bench_tled]
set -euo pipefail
bin=${1:-build/bin/bench_tled}
out=bench/results/shared_load
mkdir -p "$out"
filter='BM_TledSteps<double>/1/|BM_Assembly'
run() { # name, then environment assignments
  local name=$1; shift
 env "$@" "$bin" --benchmark_filter="$filter" --benchmark_repetitions=3 --benchmark_min_time=${MIN_TIME:-4} \
    --benchmark_report_aggregates_only=true --benchmark_format=json > "$out/$name.json.tmp"
  mv "$out/$name.json.tmp" "$out/$name.json"
}
run quiet_fixed PHYSREG_THREAD_GOVERNOR=off GOMP_SPINCOUNT=300000
run quiet_governor_long_spin PHYSREG_THREAD_GOVERNOR=on GOMP_SPINCOUNT=300000
run quiet_governor PHYSREG_THREAD_GOVERNOR=on
run quiet_governor_passive PHYSREG_THREAD_GOVERNOR=on OMP_WAIT_POLICY=passive
timeout 1200 sh -c 'while :; do :; done' &
load=$!
trap 'kill $load 2>/dev/null || true' EXIT
run busy_fixed PHYSREG_THREAD_GOVERNOR=off GOMP_SPINCOUNT=300000
run busy_governor_long_spin PHYSREG_THREAD_GOVERNOR=on GOMP_SPINCOUNT=300000
run busy_governor PHYSREG_THREAD_GOVERNOR=on
run busy_governor_passive PHYSREG_THREAD_GOVERNOR=on OMP_WAIT_POLICY=passive
kill $load
# Summary: median time per iteration of each benchmark.
python3 - "$out" <<'PY'
import glob, json, os, sys
for f in sorted(glob.glob(os.path.join(sys.argv[1], '*.json'))):
    rows = [b for b in json.load(open(f))['benchmarks'] if b.get('aggregate_name') == 'median']
    print(os.path.basename(f)[:-5].ljust(24), ' | '.join(f"{b['name'][:-7].replace('/real_time', '')}: {b['real_time']:.1f} {b['time_unit']}" for b in rows))
PY
