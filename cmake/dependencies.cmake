# SPDX-License-Identifier: GPL-3.0-or-later
# Every dependency comes from a Debian 12 package (see scripts/install-deps.sh); nothing is
# downloaded at configure time.
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(yaml-cpp REQUIRED)
find_package(fmt REQUIRED)
find_package(spdlog REQUIRED)
find_package(OpenMP REQUIRED COMPONENTS CXX)
find_package(ZLIB REQUIRED)
# ITK only behind src/io/itk_bridge.cpp: its headers are heavy and stay out of our public API. We do
# not include ITK_USE_FILE: it would put ITK's bundled Eigen on every target's include path ahead
# of Debian's Eigen 3.4. The image IO factories are registered explicitly in itk_bridge.cpp.
find_package(ITK 5.2 REQUIRED COMPONENTS
  ITKCommon ITKIOImageBase ITKIONIFTI ITKIONRRD ITKIOMeta ITKIOGDCM ITKIOPNG
  ITKDistanceMap ITKRegistrationMethodsv4 ITKRegistrationCommon ITKOptimizers ITKOptimizersv4 ITKMetricsv4 ITKPDEDeformableRegistration
  ITKDisplacementField ITKImageGrid ITKSmoothing ITKTransform ITKImageIntensity)
find_package(pugixml REQUIRED)
find_package(CGAL 5.5 REQUIRED) # Mesh_3: conforming tetrahedral meshes of label volumes (GPL-3.0-or-later)
find_package(MPI REQUIRED COMPONENTS CXX) # OpenMPI: enrichment database builds across processes and machines
find_package(NLopt 2.7 REQUIRED) # derivative-free optimisation (BOBYQA, Nelder–Mead): parameter estimation
# liblbfgs (Debian liblbfgs-dev, MIT; no CMake package): L-BFGS with the Moré–Thuente line search for
# paper 002's adjoint-gradient estimation.
find_path(LBFGS_INCLUDE_DIR lbfgs.h REQUIRED)
find_library(LBFGS_LIBRARY lbfgs REQUIRED)
# CHOLMOD (SuiteSparse 5, Debian): supernodal Cholesky of the implicit solvers' tangents. Debian's
# SuiteSparse 5 ships no CMake package, so the header and library are located directly.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse REQUIRED)
find_library(CHOLMOD_LIBRARY cholmod REQUIRED)
add_library(physreg_cholmod INTERFACE)
target_include_directories(physreg_cholmod SYSTEM INTERFACE ${CHOLMOD_INCLUDE_DIR})
target_link_libraries(physreg_cholmod INTERFACE ${CHOLMOD_LIBRARY})
# hypre (Debian libhypre-dev, built on OpenMPI): BoomerAMG-preconditioned CG for large tangents.
find_path(HYPRE_INCLUDE_DIR HYPRE.h PATH_SUFFIXES hypre REQUIRED)
find_library(HYPRE_LIBRARY HYPRE REQUIRED)
find_package(MPI REQUIRED COMPONENTS C)
add_library(physreg_hypre INTERFACE)
target_include_directories(physreg_hypre SYSTEM INTERFACE ${HYPRE_INCLUDE_DIR})
target_link_libraries(physreg_hypre INTERFACE ${HYPRE_LIBRARY} MPI::MPI_C)

# The Python module: Debian's interpreter (matching python3-dev and pybind11-dev), not whichever
# python3 comes first on PATH. Not in sanitizer builds (an instrumented module needs an
# instrumented interpreter or LD_PRELOAD tricks).
if(PHYSREG_SANITIZE)
  set(PHYSREG_BUILD_PYTHON OFF)
endif()
if(PHYSREG_BUILD_PYTHON)
  if(NOT DEFINED Python3_EXECUTABLE AND EXISTS /usr/bin/python3)
    set(Python3_EXECUTABLE /usr/bin/python3)
  endif()
  find_package(Python3 3.9 REQUIRED COMPONENTS Interpreter Development.Module)
  find_package(pybind11 2.10 CONFIG REQUIRED)
endif()
