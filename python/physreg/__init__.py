# SPDX-License-Identifier: GPL-3.0-or-later
"""physreg — biomechanical volumetric registration for image-guided surgery.

Units are millimetres, pascals and newtons; positions are in ITK's physical LPS space. Volumes are
numpy arrays indexed [z, y, x] (as SimpleITK's GetArrayFromImage), each with an ImageGeometry.

Building blocks (C++ core, arrays without copies where the layout allows):

    read_labels, read_image, read_displacement_field, write_labels, write_image,
    write_displacement_field, ImageGeometry, read_mesh, write_mesh, mesh_from_labels, Mesh,
    read_surface, write_surface, boundary_surface, Surface, read_landmarks, write_landmarks,
    tre, hausdorff

In memory (numpy arrays in, result objects out; no files):

    Model (from_labels, from_mesh; SurfaceModel.to_model) — one model for the three modes — and what is seen:
    Tool (poses), Cloud (points, labels, normals), Segmentation (label array + geometry);
    register(model, observation) → Registration (.mode, .displacement, .field(), .map_points())
    picks the solver: TLED for a tool (paper 000), co-rotational backward Euler for a cloud
    (paper 001), linear elasticity with adjoint L-BFGS for a segmentation (paper 002).
    SurfaceModel (from_labels, from_mesh), register_surface_cloud → SurfaceRegistration
    (.displacement, .field(), .map_points(), .plateaus): paper 001 with register-surface's defaults.
    ImagePair (arrays, or from_dataset), register_image_pair → ImageRegistration (.field(), .summary,
    .parameters, .landmarks): paper 002's whole pipeline, the very function register-images calls,
    with the same settings (settings_spec('register-images'): keys, defaults, ranges, help).
    PartialSurfaceCase (SurfaceModel + cloud arrays, or from_dataset), register_partial_surface →
    PartialSurfaceRegistration (.displacement(), .field(case), .summary, .landmarks): paper 001's
    whole pipeline, the function register-surface calls (settings_spec('register-surface')).
    CompressionSubject.from_dataset (the body at rest and its hexahedral model), CompressionCase
    (a Tool and its truth, or from_dataset), predict_compression → CompressionRegistration
    (.displacement, .field, .landmarks, .summary): paper 000, the function register-compression
    calls (settings_spec('register-compression')); estimate_compression → CompressionEstimation
    (.summary, .write_parameters(path)): estimate; predict_coarse_to_fine → CoarseToFine: enrich apply.

The live link (the library's live layer, as `physreg serve` runs it):

    serve(model=… | dataset=…, port=… | client='HOST:PORT', …) blocks while it serves tool poses,
    clouds and segmentations over OpenIGTLink; LiveClient('HOST:PORT') sends poses and reads the
    answers (organ surfaces, targets) as numpy arrays in mm, LPS.

One entry point per mode, named as the command and the C++ function: register_surface (paper 001),
register_images (paper 002), register_compression (paper 000), serve (live). Given the in-memory
input (PartialSurfaceCase, ImagePair, CompressionSubject and CompressionCase) each registers in
memory and returns a result object; given an output folder and the command's options it runs the
command and returns its summary. register_partial_surface, register_image_pair and
predict_compression are the in-memory routes under their 0.1 names. Single methods with their own
defaults are in physreg.methods (register, register_surface_cloud).

The commands of the `physreg` program (physreg.commands), run in this process with the same checks
and messages, each returning the summary it wrote (a dict):

    phantom, simulate, register_compression, register_surface, register_images, evaluate,
    enrich_build, enrich_apply, run

Speed: openblas_kernels() names OpenBLAS's kernels in this process; where OpenBLAS fell back to its
generic ones on a CPU it does not know, importing physreg warns once and openblas_better_kernels()
names the OPENBLAS_CORETYPE to start Python with (factorisations about 3x faster).

Errors: physreg.Error (a RuntimeError) for bad input or a failed solve, FileNotFoundError for a
missing input, TypeError/ValueError for arrays of the wrong dtype or shape.
"""
import os as _os
from pathlib import Path as _Path

# Idle OpenMP threads spin briefly, then yield the core, as in the physreg program
# (core/openmp_wait.hpp): libgomp reads this once, when the module below loads it.
if "OMP_WAIT_POLICY" not in _os.environ:
    _os.environ.setdefault("GOMP_SPINCOUNT", "1000")

# Commands run in-process draw report.html with this package's report module.
_os.environ.setdefault("PHYSREG_PYTHONPATH", str(_Path(__file__).resolve().parent.parent))

from ._physreg import (  # noqa: F401,E402
    Cloud,
    CoarseToFine,
    CompressionCase,
    CompressionEstimation,
    CompressionRegistration,
    CompressionSubject,
    Error,
    ImageGeometry,
    ImagePair,
    ImageRegistration,
    LiveClient,
    Mesh,
    Model,
    PartialSurfaceCase,
    PartialSurfaceRegistration,
    Registration,
    Segmentation,
    Surface,
    SurfaceModel,
    SurfaceRegistration,
    Tool,
    __version__,
    boundary_surface,
    estimate_compression,
    hausdorff,
    openblas_better_kernels,
    openblas_kernels,
    mesh_from_labels,
    predict_coarse_to_fine,
    read_displacement_field,
    read_image,
    read_labels,
    read_landmarks,
    read_mesh,
    read_surface,
    predict_compression,
    register,
    register_image_pair,
    register_partial_surface,
    register_surface_cloud,
    serve,
    settings_spec,
    tre,
    write_displacement_field,
    write_image,
    write_labels,
    write_landmarks,
    write_mesh,
    write_surface,
)
from . import commands, methods  # noqa: F401,E402  (the program's commands; single methods)
from .commands import *  # noqa: F401,F403,E402  (the commands also at the top level, as in 0.1)


# One name per mode, as the command and the C++ function are named: given the in-memory input it is
# the mode's entry point, given an output folder (and the command's options) it is the command.
def register_surface(*args, **kwargs):
    """Partial-surface registration (paper 001), the mode's one entry point, named as the command.

    ``register_surface(case, settings=None, progress=None, **settings)`` with a PartialSurfaceCase
    (a SurfaceModel and the cloud's (N, 3) points, mm, LPS) registers in memory and returns a
    PartialSurfaceRegistration (= register_partial_surface). ``register_surface(output, **options)``
    with an output folder runs the command ``physreg register-surface`` in this process and returns
    the summary it wrote (= commands.register_surface). The keys are settings_spec('register-surface').
    """
    if args and isinstance(args[0], PartialSurfaceCase):
        return register_partial_surface(*args, **kwargs)
    return commands.register_surface(*args, **kwargs)


def register_images(*args, **kwargs):
    """Segmentation-driven registration (paper 002), the mode's one entry point, named as the command.

    ``register_images(pair, settings=None, progress=None, **settings)`` with an ImagePair (fixed and
    moving images and labels, [z, y, x] arrays with their geometries) registers in memory and returns
    an ImageRegistration (= register_image_pair). ``register_images(output, **options)`` runs the
    command ``physreg register-images`` in this process and returns its summary
    (= commands.register_images). The keys are settings_spec('register-images').
    """
    if args and isinstance(args[0], ImagePair):
        return register_image_pair(*args, **kwargs)
    return commands.register_images(*args, **kwargs)


def register_compression(*args, **kwargs):
    """Tool-compression registration (paper 000), the mode's one entry point, named as the command.

    ``register_compression(subject, case, settings=None, progress=None, **settings)`` with a
    CompressionSubject (the body at rest and its hexahedral model) and a CompressionCase (the tracked
    tool, mm, LPS) predicts in memory and returns a CompressionRegistration (= predict_compression).
    ``register_compression(output, **options)`` runs the command ``physreg register-compression`` in
    this process and returns its summary (= commands.register_compression). The keys are
    settings_spec('register-compression').
    """
    if args and isinstance(args[0], CompressionSubject):
        return predict_compression(*args, **kwargs)
    return commands.register_compression(*args, **kwargs)


def _blas_kernels_hint():
    """OpenBLAS picks its kernels when it loads. On a CPU it does not know (a virtual machine that
    hides the model, a CPU newer than the library) it takes its generic ones, and the CHOLMOD
    factorisations run about 3x slower. The physreg program then starts itself again with better
    ones (core/blas_kernels.hpp); a Python process cannot, so it is told how, once."""
    better = openblas_better_kernels()
    if better:
        import warnings

        warnings.warn(
            f"OpenBLAS runs its generic '{openblas_kernels()}' kernels on this CPU: start Python with "
            f"OPENBLAS_CORETYPE={better} for about 3x faster factorisations",
            RuntimeWarning,
            stacklevel=3,
        )


_blas_kernels_hint()
