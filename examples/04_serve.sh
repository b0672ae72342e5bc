#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Live registration over OpenIGTLink (paper 000's mode, live): serve a phantom's body model and play
# a recorded tracker session to it, as a navigation system would send it.
#
#   examples/04_serve.sh PHYSREG DATASET
#
# PHYSREG: the program (build/bin/physreg); DATASET: a phantom dataset (`physreg phantom --preset
# small -o DIR`; ctest passes the test suite's). The recording (examples/recordings/) holds the demo
# phantom's five tool paths as `physreg serve --record` wrote them. In the operating room the
# server is started the same way and 3D Slicer's OpenIGTLinkIF (or PLUS) connects to the port.
set -euo pipefail
physreg=$1
dataset=$2
recording="$(dirname "$0")/recordings/cirs057a_seed1_tool_paths.jsonl"
work=$(mktemp -d)
trap 'rm -rf "$work"; [ -n "${server:-}" ] && kill "$server" 2>/dev/null || true' EXIT

# A free port on the loopback address (serve listens there unless --bind says otherwise).
port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')

# 1. The server: the body model of the dataset, answering each tool pose with the organ surfaces and
#    the targets; --once: it stops when its client leaves.
"$physreg" --log-level warn serve --dataset "$dataset" --grid 27x20x13 --port "$port" --once 2> "$work/serve.log" &
server=$!
for _ in $(seq 600); do grep -q listening "$work/serve.log" 2>/dev/null && break; sleep 0.1; done
grep -q listening "$work/serve.log" || { cat "$work/serve.log" >&2; exit 1; }

# 2. The tracker: the recorded session, 4x faster than it was recorded; --json: what was answered.
"$physreg" -q replay "$recording" --to "127.0.0.1:$port" --speed 4 --json > "$work/replay.json"
wait "$server"
server=
/usr/bin/python3 - "$work/replay.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
print(f"{s['poses_sent']} poses sent, last answered: {s['last_pose_answered']}; "
      f"latency median {s.get('latency_ms', {}).get('median', float('nan')):.1f} ms")
# What the example promises: every pose of the recording reached the server and the last was answered.
assert s["poses_sent"] == 105 and s["last_pose_answered"], s
PY
