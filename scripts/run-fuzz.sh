#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Builds the libFuzzer targets (clang 14, ASan + UBSan) in build-fuzz/ and runs each for
# FUZZ_SECONDS on a copy of its committed seed corpus, FUZZ_JOBS targets at a time.
# Findings (crash-*, leak-*, timeout-*, oom-*) land in build-fuzz/findings/<target>/; a summary
# (executions, coverage, features, corpus size, findings per target) in build-fuzz/fuzz-summary.json.
# Exit status 1 when any target found something. FUZZ_KEEP_GOING=1 runs libFuzzer's fork mode with
# one worker, which goes on after a finding (for long runs: every finding of the run is collected).
#   scripts/run-fuzz.sh [TARGET...]     (environment: FUZZ_SECONDS=60 FUZZ_JOBS=2 FUZZ_KEEP_GOING=0)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${FUZZ_BUILD:-$root/build-fuzz}"
seconds="${FUZZ_SECONDS:-60}"
jobs="${FUZZ_JOBS:-2}"

for tool in clang-14 clang++-14; do
  command -v "$tool" >/dev/null || { echo "run-fuzz: $tool is missing: apt-get install clang-14 libclang-rt-14-dev libomp-14-dev" >&2; exit 2; }
done
CC=clang-14 CXX=clang++-14 cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPHYSREG_FUZZ=ON -DPHYSREG_NATIVE=OFF >/dev/null
cmake --build "$build" -j"$jobs" >/dev/null

targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=($(sed -n 's/^set(PHYSREG_FUZZ_TARGETS \(.*\))$/\1/p' "$root/fuzz/CMakeLists.txt"))
fi

run_one() {
  local target="$1" build="$2" seconds="$3" root="$4" mode=()
  [ "${FUZZ_KEEP_GOING:-0}" = 1 ] && mode=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1)
  local work="$build/corpus/$target" findings="$build/findings/$target"
  rm -rf "$findings"; mkdir -p "$work" "$findings"
  # New inputs go to the working corpus; the committed seeds are read, never written.
  ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0 LSAN_OPTIONS="suppressions=$root/tests/lsan.supp" \
  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    "$build/bin/fuzz_$target" "${mode[@]}" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="$findings/" "$work" "$root/fuzz/corpus/$target" > "$build/fuzz_$target.log" 2>&1
  echo "$target exit $?"
}
export -f run_one
export FUZZ_KEEP_GOING
printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one "$@"' _ {} "$build" "$seconds" "$root" || true

# Summary from libFuzzer's final statistics and its last progress line.
python3 - "$build" "$seconds" "${targets[@]}" <<'PY'
import json, pathlib, re, sys
build, seconds, targets = pathlib.Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3:]
summary, failed = [], False
for t in targets:
    log = (build / f"fuzz_{t}.log").read_text(errors="replace")
    stat = dict(re.findall(r"stat::(\w+):\s+(\d+)", log))
    progress = re.findall(r"#(\d+)\s+\w+\s+cov: (\d+) ft: (\d+) corp: (\d+)/", log)
    forked = re.findall(r"#(\d+): cov: (\d+) ft: (\d+) corp: (\d+) ", log)  # fork mode
    if forked:
        progress, stat["number_of_executed_units"] = forked, forked[-1][0]
    findings = sorted(p.name for p in (build / "findings" / t).iterdir())
    crashed = bool(findings) or "ERROR: libFuzzer" in log or "ERROR: AddressSanitizer" in log or "runtime error" in log
    failed |= crashed
    summary.append({"target": t, "seconds": seconds, "executions": int(stat.get("number_of_executed_units", 0)),
                    "executions_per_second": int(stat.get("average_exec_per_sec", 0)),
                    "coverage_edges": int(progress[-1][1]) if progress else 0,
                    "features": int(progress[-1][2]) if progress else 0,
                    "corpus_inputs": int(progress[-1][3]) if progress else 0,
                    "peak_rss_mb": int(stat.get("peak_rss_mb", 0)), "findings": findings, "ok": not crashed})
    print(f"{t:22s} {'ok' if not crashed else 'FOUND':6s} {summary[-1]['executions']:>10d} runs  cov {summary[-1]['coverage_edges']:>5d}"
          f"  ft {summary[-1]['features']:>6d}  corpus {summary[-1]['corpus_inputs']:>5d}  {' '.join(findings)}")
# A finding on a machine we cannot reach (CI) must be reproducible from its log alone: print the
# sanitizer's report and the input, base64-encoded (`base64 -d > input; build-fuzz/bin/fuzz_T input`).
import base64
for entry in summary:
    if entry["ok"]:
        continue
    log = (build / f"fuzz_{entry['target']}.log").read_text(errors="replace").splitlines()
    report = [l for l in log if "ERROR:" in l or "runtime error" in l or l.lstrip().startswith("#") and " in " in l]
    print(f"--- {entry['target']}: sanitizer report (first 30 lines)")
    print("\n".join(report[:30]))
    for name in entry["findings"]:
        data = (build / "findings" / entry["target"] / name).read_bytes()
        print(f"--- {entry['target']}/{name} ({len(data)} bytes), base64:")
        print(base64.b64encode(data[:65536]).decode())
(build / "fuzz-summary.json").write_text(json.dumps(summary, indent=2) + "\n")
sys.exit(1 if failed else 0)
PY
