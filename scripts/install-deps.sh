#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Installs the Debian 12 packages physreg needs, if any is missing. Idempotent and quiet.
# As root it installs them; otherwise it prints the exact apt-get line and stops.
# `install-deps.sh docs` adds the documentation site's tools (make docs).
set -euo pipefail
packages=(
  cmake make g++ pkg-config
  ccache                   # compiler cache: rebuilds of the same sources (CI after a developer's build) are quick
  libinsighttoolkit5-dev   # ITK 5.2: medical image IO (NIfTI, NRRD, MetaImage, DICOM)
  libeigen3-dev            # Eigen 3.4: linear algebra
  libsuitesparse-dev       # CHOLMOD supernodal Cholesky: implicit (Newton) solves
  libhypre-dev             # hypre BoomerAMG: algebraic multigrid preconditioner (linear: pcg-amg)
  libopenblas0-openmp      # optimised BLAS/LAPACK behind CHOLMOD (replaces the reference BLAS via alternatives)
  libcli11-dev             # command line
  nlohmann-json3-dev       # JSON summaries, Slicer markups
  libyaml-cpp-dev          # tissue tables
  libspdlog-dev libfmt-dev # logging, formatting
  libpugixml-dev           # VTU (XML) reading
  libcgal-dev              # CGAL Mesh_3: conforming tetrahedral meshes of label volumes (ground-truth phantom)
  libnlopt-cxx-dev         # BOBYQA / Nelder–Mead: parameter estimation
  libfftw3-dev             # linked by ITK's registration modules (Demons, B-spline baselines)
  libopenigtlink-dev       # OpenIGTLink 1.11 (BSD): physreg serve's messages to trackers and 3D Slicer
  openigtlink-examples     # tests: OpenIGTLink's own example clients (sources) that physreg serve is tested with
  liblbfgs-dev             # L-BFGS (Nocedal; MIT): paper 002's moduli and boundary-force estimation
  libopenmpi-dev openmpi-bin # enrichment database builds across processes (mpirun)
  zlib1g-dev               # compressed VTU arrays
  python3-matplotlib       # plots of the studies (scripts/study_surface.py) and of the HTML reports
  pybind11-dev python3-dev # the Python module (import physreg)
  python3-numpy python3-pytest # the Python module's arrays and its tests
  python3-yaml             # report.html reads the phantom's ground-truth tissue table (demo)
  chromium                 # tests: report.html loads in a headless browser without console errors
  libgtest-dev libgmock-dev libbenchmark-dev
  calculix-ccx             # tests: an independent nonlinear FE solver to compare Newton with (optional at run time)
  clang-14 libclang-rt-14-dev libomp-14-dev # fuzzing: libFuzzer, ASan/UBSan runtimes, OpenMP for clang (make fuzz)
)
if [ "${1:-}" = docs ]; then
  packages+=(
    doxygen                  # the C++ API from include/ (XML for breathe)
    python3-sphinx python3-myst-parser python3-breathe python3-pydata-sphinx-theme # the site (make docs)
  )
fi
missing=()
for p in "${packages[@]}"; do
  [[ "$p" == \#* ]] && continue
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0
line="apt-get install -y --no-install-recommends ${missing[*]}"
if [ "$(id -u)" -ne 0 ]; then
  echo "physreg needs these Debian packages. Please run, as root:" >&2
  echo "  apt-get update && $line" >&2
  exit 1
fi
echo "Installing Debian packages: ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
