#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
# Rooms that fit a reader (issue 59 item 7): no source file over 800 lines, no function over 150.
# Function extents come from Universal Ctags (--fields=+ne: line and end); lambdas count inside
# the function that holds them. Usage: scripts/check_sizes.py [SOURCE_DIR]; exit 1 on a breach.
import pathlib
import shutil
import subprocess
import sys

MAX_FILE_LINES, MAX_FUNCTION_LINES = 800, 150
root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
files = sorted(p for d in ("src", "include", "apps", "python") for p in (root / d).rglob("*")
               if p.suffix in (".cpp", ".hpp", ".cu", ".py") and p.is_file() and "__pycache__" not in p.parts)
problems = []
for f in files:
    n = sum(1 for _ in f.open(errors="replace"))
    if n > MAX_FILE_LINES:
        problems.append(f"{f.relative_to(root)}: {n} lines (at most {MAX_FILE_LINES})")
if not shutil.which("ctags"):
    sys.exit("check_sizes: universal-ctags is needed for the function lengths (apt-get install universal-ctags)")
out = subprocess.run(["ctags", "--fields=+ne", "--c++-kinds=f", "--python-kinds=fm", "-o", "-", *map(str, files)],
                     capture_output=True, text=True, check=True).stdout
for line in out.splitlines():
    parts = line.split("\t")
    fields = dict(p.split(":", 1) for p in parts[3:] if ":" in p)
    if parts[0].startswith("__anon") or "line" not in fields or "end" not in fields:
        continue
    length = int(fields["end"]) - int(fields["line"]) + 1
    if length > MAX_FUNCTION_LINES:
        problems.append(f"{pathlib.Path(parts[1]).relative_to(root)}:{fields['line']}: {parts[0]} is {length} lines (at most {MAX_FUNCTION_LINES})")
for p in problems:
    print(p)
print(f"sizes: {len(files)} files, {len(problems)} over the limits")
sys.exit(1 if problems else 0)
