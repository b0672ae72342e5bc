#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# The bad-input catalogue: every subcommand fed corrupt, truncated, empty or impossible input, and
# run into unwritable folders, a full disk (RLIMIT_FSIZE) and SIGTERM/SIGINT mid-run. Each case
# must end with the expected exit code, a message naming the file/parameter and the reason, and no
# output: neither the output path nor any temporary (.tmp*) or staging (.partial*) entry beside it.
# The table in docs/bad_inputs.md is generated from the cases below and compared with this run.
#   run.sh PHYSREG [--write-docs DOCS_FILE | --check-docs DOCS_FILE]
set -u
physreg="$(readlink -f "$1")"
docs_mode="${2:-}"
docs_target="${3:-}"
here="$(cd "$(dirname "$0")" && pwd)"
work=$(mktemp -d)
chmod 755 "$work" # the read-only cases run as an unprivileged user, who must reach the inputs
trap 'chmod -R u+w "$work" 2>/dev/null; rm -rf "$work"' EXIT
failures=0
passes=0
table="$work/table.md"
: > "$table"

# case ID COMMAND INPUT FRAGMENT EXIT OUTPUT [RUNNER] -- ARGS...
#   RUNNER: plain | readonly (as user nobody, OUTPUT's folder read-only) | fsize:KB (ulimit -f) |
#           signal:NAME:SECONDS (sent mid-run)
case_() {
  local id="$1" command="$2" input="$3" fragment="$4" code="$5" output="$6" runner="plain"
  shift 6
  if [ "$1" != "--" ]; then runner="$1"; shift; fi
  shift # --
  local status
  case "$runner" in
    plain) "$physreg" "$@" </dev/null >"$work/out.txt" 2>"$work/err.txt"; status=$? ;;
    readonly)
      if [ "$(id -u)" -eq 0 ]; then
        # The copies under $work/unprivileged: the build tree may sit in a folder nobody cannot enter.
        LD_LIBRARY_PATH="$work/unprivileged/lib" setpriv --reuid=65534 --regid=65534 --clear-groups \
          "$work/unprivileged/bin/physreg" "$@" </dev/null >"$work/out.txt" 2>"$work/err.txt"; status=$?
      else
        "$physreg" "$@" </dev/null >"$work/out.txt" 2>"$work/err.txt"; status=$?
      fi ;;
    fsize:*) ( ulimit -f "${runner#fsize:}"; exec "$physreg" "$@" ) </dev/null >"$work/out.txt" 2>"$work/err.txt"; status=$? ;;
    signal:*)
      local name="${runner#signal:}" delay
      delay="${name#*:}"; name="${name%%:*}"
      # A background job of a script inherits SIGINT ignored; restore the default so the program
      # installs its handler as it would under an interactive shell.
      env --default-signal=INT,TERM "$physreg" "$@" </dev/null >"$work/out.txt" 2>"$work/err.txt" &
      local pid=$!
      # The delay counts from the moment the program has taken the signal over (blocked it for its
      # watcher thread, as /proc shows): loading a sanitizer build's libraries can take longer
      # than the delay, and a signal before main() would simply kill it.
      local number mask tries=0
      number=$(kill -l "$name")
      while mask=$(sed -n 's/^SigBlk:[[:space:]]*//p' "/proc/$pid/status" 2>/dev/null) && [ -n "$mask" ] &&
            (( ((0x$mask >> (number - 1)) & 1) == 0 && tries < 600 )); do
        sleep 0.1; tries=$((tries + 1))
      done
      sleep "$delay"; kill -s "$name" "$pid" 2>/dev/null
      wait "$pid"; status=$? ;;
  esac
  local problems=()
  [ "$status" -eq "$code" ] || problems+=("exit $status, expected $code")
  grep -qF -- "$fragment" "$work/err.txt" || problems+=("message lacks '$fragment'")
  grep -qE "internal error|AddressSanitizer|runtime error|LeakSanitizer" "$work/err.txt" && problems+=("internal error or sanitizer report")
  if [ -n "$output" ]; then
    [ -e "$output" ] && problems+=("output $output exists")
    local parent; parent="$(dirname "$output")"
    ls -A "$parent" 2>/dev/null | grep -qE '\.tmp|\.partial' && problems+=("temporary or staging entry left in $parent: $(ls -A "$parent" | grep -E '\.tmp|\.partial' | tr '\n' ' ')")
  fi
  if [ ${#problems[@]} -eq 0 ]; then
    passes=$((passes + 1))
  else
    failures=$((failures + 1))
    echo "FAILED $id ($command: $input): ${problems[*]}"
    sed 's/^/    stderr: /' "$work/err.txt" | head -5
  fi
  # The table's message: the first line that is not a log line, paths shortened, pipes escaped.
  local message; message="$(grep -v -m1 -E '^\[(trace|debug|info|warn)' "$work/err.txt" | sed "s|$work/||g; s|/tmp/[^ ']*/||g; s/|/\\\\|/g" | python3 -c "import sys; print(sys.stdin.read().rstrip(chr(10))[:180])")"
  printf '| %s | `%s` | %s | %s | %s |\n' "$id" "$command" "$input" "$message" "$code" >> "$table"
}

W="$work"
if [ "$(id -u)" -eq 0 ]; then # a copy of the program and its library that user nobody can run
  mkdir -p "$work/unprivileged/bin" "$work/unprivileged/lib"
  cp "$physreg" "$work/unprivileged/bin/"
  lib="$(ldd "$physreg" | sed -n 's/.*libphysreg[^ ]* => \(.*\) (.*/\1/p')"
  [ -n "$lib" ] && cp -L "$lib" "$work/unprivileged/lib/"
  chmod -R a+rX "$work/unprivileged"
fi
# ---------------------------------------------------------------- valid fixtures to damage
# The small phantom: ctest's shared fixture (tests/cli/make_phantom_fixture.sh, read only here), or our own.
if [ -n "${PHYSREG_TEST_PHANTOM:-}" ] && [ -f "$PHYSREG_TEST_PHANTOM/manifest.json" ]; then
  # Copied into our own folder: the read-only cases run as user nobody, who may not be able to
  # enter the build tree (CI may build in a folder only root can enter).
  cp -r "$PHYSREG_TEST_PHANTOM" "$W/ph" || { echo "fixture: cannot copy $PHYSREG_TEST_PHANTOM"; exit 1; }
  ph="$W/ph"
else
  "$physreg" -q phantom --preset small --seed 3 --depths 8,10,8,6 -o "$W/ph" >/dev/null 2>&1 || { echo "fixture: phantom failed"; exit 1; }
  ph="$W/ph"
fi
labels="$ph/rest/labels.nii.gz"
"$physreg" -q mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" --grid 12x10x8 -o "$W/m.vtu" >/dev/null 2>&1 || { echo "fixture: mesh failed"; exit 1; }
"$physreg" -q enrich build --dataset "$ph" --grid 6x5x3 --coarse-grid 3x3x3 --positions B --depths 6 -o "$W/db.phe" >/dev/null 2>&1 ||
  { echo "fixture: enrich build failed"; exit 1; }
"$physreg" -q convert "$W/m.vtu" "$W/tets.vtu" --tetrahedra >/dev/null 2>&1 || { echo "fixture: convert failed"; exit 1; }
head -c 300 "$labels" > "$W/truncated.nii.gz"
: > "$W/empty.nii.gz"
head -c 4096 /dev/urandom > "$W/garbage.nrrd"
# An all-background label volume and a 2-D image (hand-written NRRD headers + raw data).
{ printf 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 4\nencoding: raw\nspace: left-posterior-superior\n'
  printf 'space directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (0,0,0)\n\n'; head -c 64 /dev/zero; } > "$W/background.nrrd"
{ printf 'NRRD0004\ntype: uint8\ndimension: 2\nsizes: 4 4\nencoding: raw\n\n'; head -c 16 /dev/zero; } > "$W/flat.nrrd"
# Header promising 512^3 float voxels, with none.
{ printf 'NRRD0004\ntype: float\ndimension: 3\nsizes: 512 512 512\nencoding: raw\n\n'; head -c 100 /dev/zero; } > "$W/promise.nrrd"
head -c 2000 "$W/m.vtu" > "$W/truncated.vtu"
: > "$W/empty.vtu"
printf '$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 99999999999 1 99999999999\n3 1 0 99999999999\n1\n' > "$W/lying.msh"
printf 'name,x,y,z\nA,1,2,nan\n' > "$W/nan.csv"
printf 'name,x,y,z\nA,1,inf,3\n' > "$W/inf.csv"
printf 'x,y,z,label\n1,2,3,0\n1,nan,3,0\n' > "$W/cloud_nan.csv"
printf 'name,x,y,z\nfar,9000,9000,9000\n' > "$W/far.csv"
printf 'name,x,y\nA,1,2\n' > "$W/short.csv"
printf '{"markups": [{"controlPoints": [{"label": "A", "position": [1, 2]}]}]}\n' > "$W/bad.mrk.json"
printf 'tissues:\n  - {label: 1, name: p, young_modulus_pa: 2e5, poisson_ratio: 0.5}\n' > "$W/nu.yaml"
printf 'tissues:\n  - {label: 1, name: p, young_modulus_pa: -2e5, poisson_ratio: 0.45}\n' > "$W/negative_e.yaml"
printf 'tissues:\n  - {label: 1, name: p, young_modulus_pa: .nan, poisson_ratio: 0.45}\n' > "$W/nan_e.yaml"
printf 'tissues:\n  - {label: 1, name: p, young_modulus_pa: 2e5, poison_ratio: 0.45}\n' > "$W/typo.yaml"
printf 'tissues: {label: 1\n' > "$W/broken.yaml"
cat > "$W/case_nu.yaml" <<CASE
mesh: $W/m.vtu
tissues: $W/nu.yaml
solver: {method: newton}
constraints: [{name: base, select: {face: y_max, tolerance_mm: 3}, fixed: [x, y, z]}]
forces: [{name: pull, select: {face: y_min, tolerance_mm: 3}, total_force_n: [0, -0.1, 0]}]
output: {directory: $W/sim_nu}
CASE
sed "s|tissues: .*|tissues: $ph/ground_truth_tissues.yaml|; s|sim_nu|sim_blowup|; s|total_force_n: \[0, -0.1, 0\]|total_force_n: [0, -1e9, 0]|; s|solver: {method: newton}|solver: {method: newton, max_load_cuts: 2, max_iterations: 10}|" "$W/case_nu.yaml" > "$W/case_blowup.yaml"
sed "s|solver: {method: newton}|solver: {method: newton, load_steps: 2.5}|; s|sim_nu|sim_steps|; s|tissues: .*|tissues: $ph/ground_truth_tissues.yaml|" "$W/case_nu.yaml" > "$W/case_steps.yaml"
sed "s|solver: {method: newton}|solver: fast|; s|sim_nu|sim_scalar|" "$W/case_nu.yaml" > "$W/case_scalar.yaml"
cp "$W/db.phe" "$W/flipped.phe"; printf '\xff' | dd of="$W/flipped.phe" bs=1 seek=1500 conv=notrunc status=none
head -c 1000 "$W/db.phe" > "$W/truncated.phe"
cp -r "$ph" "$W/ph_nolabels"; rm "$W/ph_nolabels/rest/labels.nii.gz"
cp -r "$ph" "$W/ph_badmanifest"; printf '{"version": 1, "states": [' > "$W/ph_badmanifest/manifest.json"
cp -r "$ph" "$W/ph_badpercent" # a partial surface listed under "ten" instead of a percentage
python3 - "$W/ph_badpercent/manifest.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
state = next(s for s in m["states"] if s["partial_surfaces"])
state["partial_surfaces"]["ten"] = state["partial_surfaces"].pop(next(iter(state["partial_surfaces"])))
json.dump(m, open(sys.argv[1], "w"))
PY
cat > "$W/params_negative.json" <<'JSON'
{"format": "physreg-model-parameters", "format_version": 1, "variant": "coupled",
 "coupling_stiffness_n_per_m": {"parenchyma_tumour": -3, "parenchyma_vessel": 500},
 "young_modulus_pa": {"parenchyma": 2e5, "tumour": 5e6, "vessel": 1e6}, "poisson_ratio": 0.49,
 "grid_cells": [36, 27, 12], "mls_support_radius_cells": 1.25, "mesh_fingerprint": "x"}
JSON
sed 's/"poisson_ratio": 0.49/"poisson_ratio": 0.5/; s/-3/600/' "$W/params_negative.json" > "$W/params_nu.json"
printf 'not json' > "$W/params_garbage.json"
mkdir -p "$W/ro"; chmod 555 "$W/ro"
mkdir -p "$W/full"

# ---------------------------------------------------------------- the catalogue
o="$W/out"
case_ mesh-truncated mesh "truncated NIfTI (300 of its bytes)" "truncated.nii.gz" 1 "$o.vtu" -- mesh "$W/truncated.nii.gz" -o "$o.vtu"
case_ mesh-empty mesh "empty file" "empty.nii.gz" 1 "$o.vtu" -- mesh "$W/empty.nii.gz" -o "$o.vtu"
case_ mesh-garbage mesh "random bytes named .nrrd" "garbage.nrrd" 1 "$o.vtu" -- mesh "$W/garbage.nrrd" -o "$o.vtu"
case_ mesh-background mesh "label volume with no tissue voxel" "no" 1 "$o.vtu" -- mesh "$W/background.nrrd" -o "$o.vtu"
case_ mesh-2d mesh "2-D image" "3-D" 1 "$o.vtu" -- mesh "$W/flat.nrrd" -o "$o.vtu"
case_ mesh-promise mesh "header declaring 512³ floats, data missing" "promise.nrrd" 1 "$o.vtu" -- mesh "$W/promise.nrrd" -o "$o.vtu"
case_ mesh-nu mesh "tissue table with ν = 0.5" "poisson" 1 "$o.vtu" -- mesh "$labels" --tissues "$W/nu.yaml" -o "$o.vtu"
case_ mesh-negative-e mesh "tissue table with E < 0" "young_modulus_pa" 1 "$o.vtu" -- mesh "$labels" --tissues "$W/negative_e.yaml" -o "$o.vtu"
case_ mesh-nan-e mesh "tissue table with E = NaN" "young_modulus_pa" 1 "$o.vtu" -- mesh "$labels" --tissues "$W/nan_e.yaml" -o "$o.vtu"
case_ mesh-typo mesh "tissue table with a misspelt key" "did you mean 'poisson_ratio'" 1 "$o.vtu" -- mesh "$labels" --tissues "$W/typo.yaml" -o "$o.vtu"
case_ mesh-broken-yaml mesh "tissue table that is not YAML" "broken.yaml" 1 "$o.vtu" -- mesh "$labels" --tissues "$W/broken.yaml" -o "$o.vtu"
case_ mesh-grid mesh "--grid 0x4x4" "grid" 1 "$o.vtu" -- mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" --grid 0x4x4 -o "$o.vtu"
case_ mesh-overlap mesh "--tetrahedra onto the -o file" "same file" 1 "$o.vtu" -- mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" -o "$o.vtu" --tetrahedra "$o.vtu"
case_ mesh-readonly mesh "read-only output folder" "ro" 1 "$W/ro/m.vtu" readonly -- mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" -o "$W/ro/m.vtu"
case_ mesh-missing-dir mesh "output folder does not exist" "does not exist" 1 "$W/nowhere/m.vtu" -- mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" -o "$W/nowhere/m.vtu"
case_ mesh-full-disk mesh "disk full (file size limit 16 KB)" "full.vtu" 1 "$W/full/full.vtu" fsize:16 -- mesh "$labels" --tissues "$ph/ground_truth_tissues.yaml" -o "$W/full/full.vtu"
case_ coarsen-truncated coarsen "truncated VTU" "truncated.vtu" 1 "$o.vtu" -- coarsen "$W/truncated.vtu" --grid 4x4x4 -o "$o.vtu"
case_ coarsen-empty coarsen "empty VTU" "empty.vtu" 1 "$o.vtu" -- coarsen "$W/empty.vtu" --grid 4x4x4 -o "$o.vtu"
case_ coarsen-grid coarsen "--grid finer than the mesh" "grid" 1 "$o.vtu" -- coarsen "$W/m.vtu" --grid 400x400x400 -o "$o.vtu"
case_ info-garbage info "random bytes named .nrrd" "garbage.nrrd" 1 "" -- info "$W/garbage.nrrd"
case_ info-lying-msh info "Gmsh file whose counts exceed the file" "larger than the file" 1 "" -- info "$W/lying.msh"
case_ info-missing info "file that does not exist" "does not exist" 1 "" -- info "$W/missing.vtu"
case_ convert-truncated convert "truncated NIfTI" "truncated.nii.gz" 1 "$o.nrrd" -- convert "$W/truncated.nii.gz" "$o.nrrd"
case_ convert-nan-landmarks convert "landmark with NaN" "nan.csv" 1 "$o.fcsv" -- convert "$W/nan.csv" "$o.fcsv"
case_ convert-inf-landmarks convert "landmark with Inf" "inf.csv" 1 "$o.fcsv" -- convert "$W/inf.csv" "$o.fcsv"
case_ convert-short-landmarks convert "CSV without z column" "short.csv" 1 "$o.fcsv" -- convert "$W/short.csv" "$o.fcsv"
case_ convert-markups convert "markups point with 2 coordinates" "bad.mrk.json" 1 "$o.csv" -- convert "$W/bad.mrk.json" "$o.csv"
case_ convert-unknown convert "unknown output extension" ".xyz" 1 "$o.xyz" -- convert "$W/m.vtu" "$o.xyz"
case_ locate-outside "landmarks locate" "landmark outside the mesh" "outside the mesh" 1 "$o.csv" -- landmarks locate "$W/m.vtu" "$W/far.csv" -o "$o.csv"
case_ locate-nan "landmarks locate" "landmark with NaN" "nan.csv" 1 "$o.csv" -- landmarks locate "$W/m.vtu" "$W/nan.csv" -o "$o.csv"
case_ simulate-nu simulate "case whose tissue has ν = 0.5" "poisson" 1 "$W/sim_nu" -- simulate "$W/case_nu.yaml"
case_ simulate-steps simulate "load_steps: 2.5" "whole number" 1 "$W/sim_steps" -- simulate "$W/case_steps.yaml"
case_ simulate-scalar simulate "'solver: fast' (a scalar for a map)" "must be a map" 1 "$W/sim_scalar" -- simulate "$W/case_scalar.yaml"
case_ simulate-diverges simulate "force of 1e9 N (Newton cannot converge)" "did not converge" 1 "$W/sim_blowup" -- simulate "$W/case_blowup.yaml"
case_ phantom-preset phantom "unknown preset" "preset" 1 "$o" -- phantom --preset giant -o "$o"
case_ phantom-depths phantom "negative tool depth" "depth" 1 "$o" -- phantom --preset small --depths 8,-1,8,6 -o "$o"
case_ phantom-full-disk phantom "disk full (file size limit 32 KB)" "File too large" 1 "$o" fsize:32 -- phantom --preset small -o "$o"
case_ phantom-sigterm phantom "SIGTERM after 3 s" "interrupted by SIGTERM" 143 "$o" signal:TERM:3 -- phantom --preset small -o "$o"
case_ phantom-sigint phantom "SIGINT (Ctrl-C) after 3 s" "interrupted by SIGINT" 130 "$o" signal:INT:3 -- phantom --preset small -o "$o"
case_ estimate-no-labels estimate "dataset without its rest labels" "labels.nii.gz" 1 "$o.json" -- estimate --dataset "$W/ph_nolabels" -o "$o.json"
case_ estimate-manifest estimate "dataset with a truncated manifest.json" "manifest.json" 1 "$o.json" -- estimate --dataset "$W/ph_badmanifest" -o "$o.json"
case_ estimate-manifest-key estimate "manifest.json with a partial surface under 'ten'" "'ten' is not a percentage" 1 "$o.json" -- estimate --dataset "$W/ph_badpercent" -o "$o.json"
case_ estimate-k-bounds estimate "--k-bounds abc 5" "Could not convert: --k-bounds" 104 "$o.json" -- estimate --dataset "$ph" --k-bounds abc 5 -o "$o.json"
case_ register-compression-params register-compression "parameter file with negative stiffness" "params_negative.json" 1 "$o" -- register-compression --dataset "$ph" --grid 36x27x12 --state D --parameters "$W/params_negative.json" -o "$o"
case_ register-compression-nu register-compression "parameter file with ν = 0.5" "params_nu.json" 1 "$o" -- register-compression --dataset "$ph" --grid 36x27x12 --state D --parameters "$W/params_nu.json" -o "$o"
case_ register-compression-garbage register-compression "parameter file that is not JSON" "params_garbage.json" 1 "$o" -- register-compression --dataset "$ph" --grid 36x27x12 --state D --parameters "$W/params_garbage.json" -o "$o"
case_ register-compression-state register-compression "unknown state" "Z" 1 "$o" -- register-compression --dataset "$ph" --grid 36x27x12 --state Z -o "$o"
case_ register-compression-overlap register-compression "output = the dataset folder" "not empty" 1 "" -- register-compression --dataset "$ph" --grid 36x27x12 --state D -o "$ph"
case_ register-compression-full-disk register-compression "disk full (file size limit 64 KB)" "File too large" 1 "$o" fsize:64 -- register-compression --dataset "$ph" --grid 36x27x12 --state D -o "$o"
case_ register-compression-sigterm register-compression "SIGTERM mid-run" "interrupted by SIGTERM" 143 "$o" signal:TERM:0.5 -- register-compression --dataset "$ph" --grid 36x27x12 --state D -o "$o"
case_ register-surface-cloud register-surface "point cloud with NaN" "cloud_nan.csv" 1 "$o" -- register-surface --model "$W/tets.vtu" --cloud "$W/cloud_nan.csv" -o "$o"
case_ register-surface-visible register-surface "--visible 77 (not in the dataset)" "77" 1 "$o" -- register-surface --dataset "$ph" --visible 77 -o "$o"
case_ register-surface-readonly register-surface "read-only output folder" "ro" 1 "$W/ro/rs" readonly -- register-surface --dataset "$ph" --visible 50 -o "$W/ro/rs"
case_ register-images-truncated register-images "truncated fixed image" "truncated.nii.gz" 1 "$o" -- register-images --fixed "$W/truncated.nii.gz" --fixed-labels "$labels" --moving "$labels" --moving-labels "$labels" -o "$o"
case_ register-images-background register-images "moving segmentation without structures" "background.nrrd" 1 "$o" -- register-images --fixed "$labels" --fixed-labels "$labels" --moving "$W/background.nrrd" --moving-labels "$W/background.nrrd" -o "$o"
case_ register-images-landmarks register-images "fixed landmarks with Inf" "inf.csv" 1 "$o" -- register-images --fixed "$labels" --fixed-labels "$labels" --moving "$labels" --moving-labels "$labels" --landmarks-fixed "$W/inf.csv" --landmarks-moving "$ph/rest/landmarks.csv" -o "$o"
case_ register-images-prior register-images "--moduli-prior 0.5 (below 1)" "--moduli-prior 0.5" 1 "$o" -- register-images --fixed "$labels" --fixed-labels "$labels" --moving "$labels" --moving-labels "$labels" --moduli-prior 0.5 -o "$o"
case_ register-images-one-image register-images "--fixed image without --moving" "with --fixed and --moving for their images" 1 "$o" -- register-images --fixed "$labels" --fixed-labels "$labels" --moving-labels "$labels" -o "$o"
case_ register-images-labels-intensity register-images "label maps only, --baselines intensity" "--baselines intensity needs the --fixed and --moving images" 1 "$o" -- register-images --fixed-labels "$labels" --moving-labels "$labels" --baselines intensity -o "$o"
case_ register-images-sigint register-images "SIGINT mid-run" "interrupted by SIGINT" 130 "$o" signal:INT:4 -- register-images --dataset "$ph" -o "$o"
case_ evaluate-nan evaluate "predicted landmark with NaN" "nan.csv" 1 "$o" -- evaluate --predicted "$W/nan.csv" --truth "$ph/states/D/landmarks.csv" -o "$o"
case_ evaluate-readonly evaluate "read-only output folder" "Permission denied" 1 "$W/ro/tre" readonly -- evaluate --predicted "$ph/states/D/landmarks.csv" --truth "$ph/states/D/landmarks.csv" -o "$W/ro/tre"
case_ evaluate-unmatched evaluate "no landmark names in common" "no prediction" 1 "$o" -- evaluate --predicted "$W/far.csv" --truth "$ph/states/D/landmarks.csv" -o "$o"
case_ enrich-build-depths "enrich build" "depths not increasing" "depth" 1 "$o.phe" -- enrich build --dataset "$ph" --grid 6x5x3 --coarse-grid 3x3x3 --depths 6,4 -o "$o.phe"
case_ enrich-build-grid "enrich build" "--coarse-grid 0x3x3" "grid" 1 "$o.phe" -- enrich build --dataset "$ph" --grid 6x5x3 --coarse-grid 0x3x3 -o "$o.phe"
case_ enrich-apply-flipped "enrich apply" "database with one flipped byte" "checksum" 1 "$o" -- enrich apply --database "$W/flipped.phe" --dataset "$ph" --grid 6x5x3 --state D -o "$o"
case_ enrich-apply-truncated "enrich apply" "truncated database" "truncated.phe" 1 "$o" -- enrich apply --database "$W/truncated.phe" --dataset "$ph" --grid 6x5x3 --state D -o "$o"
case_ enrich-apply-other-mesh "enrich apply" "database built for another mesh" "another fine mesh" 1 "$o" -- enrich apply --database "$W/db.phe" --dataset "$ph" --grid 8x6x4 --state D -o "$o"
case_ bench-enrich-database "bench enrich" "truncated database" "truncated.phe" 1 "$o.json" -- bench enrich --dataset "$ph" --grid 6x5x3 --database "$W/truncated.phe" --states D -o "$o.json"
case_ bench-condensed-steps "bench condensed" "--steps 0" "--steps must be" 1 "$o.json" -- bench condensed --dataset "$ph" --grid 6x5x3 --steps 0 -o "$o.json"
case_ bench-condensed-state "bench condensed" "a state that is not a tool compression" "insufflation" 1 "$o.json" -- bench condensed --dataset "$ph" --grid 6x5x3 --states insufflation -o "$o.json"
case_ bench-condensed-memory-syntax "bench condensed" "--memory-limit 8X" "--memory-limit must be auto or a positive size" 1 "$o.json" -- bench condensed --dataset "$ph" --grid 6x5x3 --memory-limit 8X -o "$o.json"
case_ register-compression-memory-limit register-compression "--solver condensed over --memory-limit 1M" "over the memory limit" 1 "$o" -- register-compression --dataset "$ph" --grid 12x9x6 --state D --solver condensed --memory-limit 1M -o "$o"
case_ demo-readonly demo "read-only output folder" "ro" 1 "$W/ro/demo" readonly -- demo --quick -o "$W/ro/demo"
case_ demo-sigterm demo "SIGTERM mid-run" "interrupted by SIGTERM" 143 "$o" signal:TERM:5 -- demo --quick -o "$o"
case_ cli-unknown-option "(any)" "unknown option" "--frobnicate" 109 "" -- mesh "$labels" -o "$o.vtu" --frobnicate

# ---------------------------------------------------------------- the table in docs/
{
  echo "| case | command | input | message (first line of stderr; paths shortened) | exit |"
  echo "|---|---|---|---|---|"
  cat "$table"
} > "$work/table_full.md"
if [ -n "$docs_target" ]; then
  python3 - "$docs_mode" "$docs_target" "$work/table_full.md" <<'PY' || failures=$((failures + 1))
import pathlib, sys
mode, doc, table = sys.argv[1], pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3]).read_text()
text = doc.read_text()
start, end = "<!-- catalogue:start -->\n", "<!-- catalogue:end -->"
a, b = text.index(start) + len(start), text.index(end)
# Compare the cases, inputs and exit codes (messages carry run-specific numbers such as PIDs).
rows = lambda t: [tuple(c.strip() for i, c in enumerate(r.split(" | ")) if i != 3) for r in t.strip().splitlines()]
if mode == "--write-docs":
    doc.write_text(text[:a] + table + text[b:])
    print(f"wrote the table into {doc}")
elif rows(text[a:b]) != rows(table):
    print(f"FAILED: the catalogue table in {doc} is out of date: run tests/cli/bad_inputs/run.sh PHYSREG --write-docs {doc}")
    sys.exit(1)
PY
fi
echo "bad-input catalogue: $passes checks passed, $failures failed ($(wc -l < "$table") cases)"
[ "$failures" -eq 0 ]
