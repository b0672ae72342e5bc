#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# The GPU path's check on a machine with an NVIDIA device (issue 45): build with the CUDA toolkit,
# run the GPU unit tests (the device must equal the CPU path to 1e-10 of the peak displacement),
# then bench_tled's CPU and GPU explicit steps in one run, JSON into $OUT (default bench/results).
# Usage: bash bench/gpu_check.sh [BUILD_DIR]   (about 10 min on 16 cores, most of it the build)
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build-gpu}"
out="${OUT:-bench/results}"
mkdir -p "$out"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu_check_device.txt" || true
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DPHYSREG_CUDA=ON -DPHYSREG_BUILD_PYTHON=OFF >/dev/null
cmake --build "$build" -j"$(nproc)" --target physreg_tests bench_tled
"$build"/tests/physreg_tests --gtest_filter='GpuPath.*:MechanicsTled.Band*' 2>&1 | tee "$out/gpu_check_tests.txt"
# CPU on 2 threads (the issue's reference) and the GPU, same blocks, same run.
OMP_NUM_THREADS=2 "$build"/bin/bench_tled --benchmark_filter='BM_TledSteps<double>/1/2/0|BM_TledStepsGpu' \
  --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
  --benchmark_out="$out/bench_tled_gpu.json" --benchmark_out_format=json
