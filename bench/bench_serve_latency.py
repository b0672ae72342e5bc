#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# physreg serve's latency on loopback (issue 44 targets): the model prepared once (physreg prepare),
# then for each rate a fresh `serve MODEL --record` and `physreg replay --dataset` streaming the
# dataset's tool paths as a tracker would. Measured per rate:
#   - ready: seconds from starting serve to its "listening" line (the prepared model read);
#   - server-side latency: a TRANSFORM read → the first POLYDATA sent with its timestamp (from the
#     server's own --record wall times), p50 / p95 / p99 / max, ms;
#   - round trip: replay's pose sent → the POINT answer received (its own summary);
#   - poses answered and dropped (the latest pose wins: at rates above the update rate most poses
#     are dropped, and latency must not grow);
#   - the server's resident memory (VmRSS) sampled every second: first, last, largest.
# Usage: /usr/bin/python3 bench/bench_serve_latency.py DATASET OUT.json [--rates 60,500] [--seconds 20]
#        [--model DIR (reuse a prepared model)] [--physreg build/bin/physreg]
import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
parser = argparse.ArgumentParser()
parser.add_argument("dataset")
parser.add_argument("output")
parser.add_argument("--physreg", default=os.path.join(ROOT, "build", "bin", "physreg"))
parser.add_argument("--rates", default="60,500")
parser.add_argument("--seconds", type=float, default=20.0, help="length of each streamed session")
parser.add_argument("--states", default="A,B,C,D,E")
parser.add_argument("--model", default="", help="a prepared model to reuse (else prepared here)")
args = parser.parse_args()
work = tempfile.mkdtemp(prefix="physreg_serve_bench_")


def percentile(values, q):
    values = sorted(values)
    if not values:
        return None
    k = (len(values) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(values) - 1)
    return values[lo] + (values[hi] - values[lo]) * (k - lo)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mb(pid):
    try:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


result = {"dataset": os.path.abspath(args.dataset), "host": os.uname().nodename, "date": time.strftime("%Y-%m-%d %H:%M"),
          "threads": os.environ.get("OMP_NUM_THREADS", "default"), "runs": []}
model = args.model
if not model:
    model = os.path.join(work, "model")
    started = time.time()
    r = subprocess.run([args.physreg, "-q", "prepare", "--dataset", args.dataset, "-o", model, "--json"], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"prepare failed: {r.stderr}")
    result["prepare"] = json.loads(r.stdout)
    result["prepare"]["wall_s"] = time.time() - started
    print(f"prepare: {result['prepare']['seconds']:.1f} s", flush=True)

states = args.states.split(",")
for rate in [float(x) for x in args.rates.split(",")]:
    port = free_port()
    record = os.path.join(work, f"record_{int(rate)}.jsonl")
    started = time.time()
    server = subprocess.Popen([args.physreg, "--log-level", "info", "serve", model, "--port", str(port), "--once", "--record", record],
                              stderr=subprocess.PIPE, text=True)
    log = []
    while True:
        line = server.stderr.readline()
        if not line:
            sys.exit("serve ended before listening:\n" + "".join(log))
        log.append(line)
        if "listening" in line:
            break
    ready_s = time.time() - started
    drain = threading.Thread(target=lambda: log.extend(server.stderr), daemon=True)
    drain.start()
    memory = []
    stop = threading.Event()

    def sample():
        while not stop.is_set():
            value = rss_mb(server.pid)
            if value is not None:
                memory.append((time.time() - started, value))
            stop.wait(1.0)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    steps = max(2, int(round(args.seconds * rate / len(states))))
    summary_file = os.path.join(work, f"replay_{int(rate)}.json")
    replay = subprocess.run([args.physreg, "-q", "replay", "--dataset", args.dataset, "--states", args.states, "--steps", str(steps),
                             "--rate", str(rate), "--to", f"127.0.0.1:{port}", "-o", summary_file], capture_output=True, text=True)
    server.wait(timeout=120)
    stop.set()
    sampler.join()
    if replay.returncode != 0 or server.returncode != 0:
        sys.exit(f"replay exit {replay.returncode}: {replay.stderr}\nserve exit {server.returncode}: {''.join(log)}")
    # Server-side latency: TRANSFORM in → first POLYDATA out carrying its timestamp.
    arrived, answered = {}, {}
    for line in open(record):
        m = json.loads(line)
        if m["direction"] == "in" and m["type"] == "TRANSFORM":
            arrived[m["timestamp"]] = m["wall_s"]
        elif m["direction"] == "out" and m["type"] == "POLYDATA" and m["timestamp"] in arrived and m["timestamp"] not in answered:
            answered[m["timestamp"]] = m["wall_s"]
    latency_ms = [1000.0 * (answered[t] - arrived[t]) for t in answered]
    # Latency must not grow: compare the first and last fifth of the session.
    fifth = max(1, len(latency_ms) // 5)
    rss = [v for _, v in memory]
    run = {
        "rate_hz": rate, "poses_sent": len(arrived), "poses_answered": len(answered), "poses_dropped": len(arrived) - len(answered),
        "ready_s": ready_s,
        "server_latency_ms": {"p50": percentile(latency_ms, 0.5), "p95": percentile(latency_ms, 0.95), "p99": percentile(latency_ms, 0.99),
                              "max": max(latency_ms) if latency_ms else None,
                              "median_first_fifth": statistics.median(latency_ms[:fifth]) if latency_ms else None,
                              "median_last_fifth": statistics.median(latency_ms[-fifth:]) if latency_ms else None},
        "round_trip": json.load(open(summary_file)),
        "rss_mb": {"first": rss[0] if rss else None, "last": rss[-1] if rss else None, "max": max(rss) if rss else None,
                   "samples": len(rss), "growth_last_vs_first_percent": 100.0 * (rss[-1] / rss[0] - 1.0) if len(rss) > 1 else None},
    }
    result["runs"].append(run)
    lat = run["server_latency_ms"]
    print(f"{rate:g} Hz: ready {ready_s:.2f} s; {run['poses_answered']}/{run['poses_sent']} poses answered; server latency p50 {lat['p50']:.2f} "
          f"p99 {lat['p99']:.2f} max {lat['max']:.2f} ms; RSS {run['rss_mb']['first']:.0f} → {run['rss_mb']['last']:.0f} MB", flush=True)

os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
json.dump(result, open(args.output, "w"), indent=1)
print(f"written {args.output}")
