#!/usr/bin/env bash
# End-to-end checks of the physreg program: outputs, exit codes, messages, no partial files.
set -u
physreg="$1"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failures=0
passes=0

pass() { passes=$((passes + 1)); }
failed() { echo "FAILED: $*"; failures=$((failures + 1)); }

# expect_ok DESCRIPTION -- command...
expect_ok() {
  local what="$1"; shift
  if "$@" >"$work/out.txt" 2>"$work/err.txt"; then pass; else failed "$what (exit $?)"; cat "$work/err.txt"; fi
}
# expect_error DESCRIPTION MESSAGE_FRAGMENT -- command...: non-zero exit and the fragment on stderr
expect_error() {
  local what="$1" fragment="$2"; shift 2
  if "$@" >"$work/out.txt" 2>"$work/err.txt"; then
    failed "$what: exit 0, expected an error"
  elif ! grep -qF -- "$fragment" "$work/err.txt"; then
    failed "$what: message lacks '$fragment':"; cat "$work/err.txt"
  else pass; fi
}
expect_file() { if [ -s "$1" ]; then pass; else failed "missing output $1"; fi; }
expect_no_file() {
  if [ -e "$1" ]; then failed "output $1 should not exist"; else pass; fi
  if ls -a "$(dirname "$1")" | grep -q '\.tmp'; then failed "temporary file left in $(dirname "$1")"; else pass; fi
}

expect_ok "--version" "$physreg" --version
grep -q "physreg 0" "$work/out.txt" && pass || failed "--version prints the version"
expect_ok "--help" "$physreg" --help
for sub in mesh coarsen info convert demo "landmarks locate"; do
  expect_ok "$sub --help" "$physreg" $sub --help
done

# The main job on the built-in phantom.
expect_ok "demo" "$physreg" --log-level warn demo -o "$work/demo"
for f in labels.nii.gz tissues.yaml landmarks.csv landmarks.mrk.json landmarks.fcsv mesh_voxels.vtu \
         mesh_fine.vtu mesh_coarse.vtu surfaces_fine.ply boundary_fine.stl tetrahedra_fine.vtu summary.json; do
  expect_file "$work/demo/$f"
done
d="$work/demo"

# mesh + info + coarsen + landmarks + convert on the demo's label volume.
expect_ok "mesh" "$physreg" mesh "$d/labels.nii.gz" --tissues "$d/tissues.yaml" --grid 40x30x20 -o "$work/m.vtu" \
  --surface "$work/s.ply" --tetrahedra "$work/t.msh" --json
grep -q '"cell_type": "hexahedron"' "$work/out.txt" && pass || failed "mesh --json summary"
expect_file "$work/m.vtu"; expect_file "$work/s.ply"; expect_file "$work/t.msh"
expect_ok "info image" "$physreg" info "$d/labels.nii.gz" --json
grep -q '"voxels"' "$work/out.txt" && pass || failed "info lists label voxel counts"
expect_ok "info mesh" "$physreg" info "$work/m.vtu"
grep -q "min_scaled_jacobian" "$work/out.txt" && pass || failed "info reports mesh quality"
expect_ok "info gmsh" "$physreg" info "$work/t.msh" --json
grep -q '"tetrahedron"' "$work/out.txt" && pass || failed "info reads the tetrahedral .msh"
expect_ok "coarsen" "$physreg" coarsen "$work/m.vtu" --grid 12x10x8 -o "$work/c.vtu" --embedding "$work/e.csv"
expect_file "$work/c.vtu"; expect_file "$work/e.csv"
[ "$(($(wc -l <"$work/e.csv") - 1))" -gt 1000 ] && pass || failed "embedding lists every fine node"
expect_ok "landmarks locate" "$physreg" landmarks locate "$d/mesh_fine.vtu" "$d/landmarks.csv" -o "$work/where.csv"
grep -q "^tumour_1," "$work/where.csv" && pass || failed "landmark located"
expect_ok "convert landmarks" "$physreg" convert "$d/landmarks.mrk.json" "$work/l.fcsv"
expect_ok "convert mesh" "$physreg" convert "$d/mesh_coarse.vtu" "$work/c.v2.msh"
expect_ok "convert image" "$physreg" convert "$d/labels.nii.gz" "$work/labels.nrrd"

# Bad input: clear message, non-zero exit, nothing written.
expect_error "missing labels" "nope.nii.gz" "$physreg" mesh "$work/nope.nii.gz" -o "$work/x.vtu"
expect_no_file "$work/x.vtu"
head -c 3000 "$d/labels.nii.gz" > "$work/cut.nii.gz"
expect_error "truncated labels" "cut.nii.gz" "$physreg" mesh "$work/cut.nii.gz" -o "$work/x.vtu"
expect_no_file "$work/x.vtu"
printf 'tissues:\n  - {label: 1, name: parenchyma, young_modulus_pa: 2e5, poisson_ratio: 0.49}\n' > "$work/one.yaml"
expect_error "label missing from table" "not in the tissue table" "$physreg" mesh "$d/labels.nii.gz" --tissues "$work/one.yaml" -o "$work/x.vtu"
expect_no_file "$work/x.vtu"
printf 'tissues:\n  - {label: 1, name: parenchyma, young_modulus_pa: 2e5, poisson_ratio: 0.5}\n' > "$work/nu.yaml"
expect_error "impossible Poisson ratio" "poisson_ratio" "$physreg" mesh "$d/labels.nii.gz" --tissues "$work/nu.yaml" -o "$work/x.vtu"
expect_error "grid larger than image" "larger" "$physreg" mesh "$d/labels.nii.gz" --grid 500x30x20 -o "$work/x.vtu"
expect_no_file "$work/x.vtu"
expect_error "bad grid" "--grid" "$physreg" mesh "$d/labels.nii.gz" --grid 40x30 -o "$work/x.vtu"
expect_error "missing output dir" "does not exist" "$physreg" mesh "$d/labels.nii.gz" -o "$work/no/x.vtu"
printf 'name,x,y,z\nfar,1000,0,0\n' > "$work/far.csv"
expect_error "landmark outside" "outside the mesh" "$physreg" landmarks locate "$d/mesh_fine.vtu" "$work/far.csv" -o "$work/w.csv"
expect_no_file "$work/w.csv"
printf '{"markups": [' > "$work/broken.mrk.json"
expect_error "unreadable markups" "broken.mrk.json" "$physreg" info "$work/broken.mrk.json"
head -c 20000 "$d/mesh_fine.vtu" > "$work/cut.vtu"
expect_error "truncated mesh" "cut.vtu" "$physreg" coarsen "$work/cut.vtu" --grid 5x5x5 -o "$work/x.vtu"
expect_no_file "$work/x.vtu"
expect_error "coarsen needs a grid mesh" "uniform grid" "$physreg" coarsen "$work/t.msh" --grid 5x5x5 -o "$work/x.vtu"
expect_error "unknown subcommand" "" "$physreg" frobnicate

echo "$passes passed, $failures failed"
[ "$failures" -eq 0 ]
