# SPDX-License-Identifier: GPL-3.0-or-later
"""The physreg program's commands as Python functions.

Keyword arguments are the command's options with '-' written '_' (``field_spacing=1.0`` is
``--field-spacing 1.0``); True adds a flag, None/False leaves an option out, a list or tuple gives
an option several values. ``output`` is ``-o``. Each function runs the command in this process
(the same validations and error messages as the program), then returns the JSON summary it wrote.
``progress(label, fraction, message)`` replaces the terminal's progress bar; ``quiet=True``
silences progress and info logs.
"""
import json
import os
from pathlib import Path

from . import _physreg


def _arguments(command, positional, options):
    args = []
    quiet = options.pop("quiet", False)
    if quiet:
        args.append("--quiet")
    args += command.split()
    args += [os.fspath(p) for p in positional]
    for key, value in options.items():
        if value is None or value is False:
            continue
        flag = "-o" if key == "output" else "--" + key.replace("_", "-")
        if value is True:
            args.append(flag)
        elif isinstance(value, (list, tuple)):
            args.append(flag)
            args += [os.fspath(v) if isinstance(v, os.PathLike) else str(v) for v in value]
        else:
            args += [flag, os.fspath(value) if isinstance(value, os.PathLike) else str(value)]
    return args


def run(command, *positional, progress=None, **options):
    """Runs ``physreg COMMAND POSITIONAL... --OPTIONS`` in this process; returns None.

    Example: ``physreg.run("mesh", "labels.nii.gz", output="mesh.vtu", grid="20x20x10")``.
    Raises physreg.Error (bad input, with the program's message), FileNotFoundError (missing
    input) and KeyboardInterrupt from the progress callback's signal check.
    """
    _physreg.run(_arguments(command, positional, options), progress)


def _summary(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def _command_with_folder(command, output, summary_name, progress, options):
    if output is None:
        raise TypeError(f"{command.replace('-', '_')}() needs output= (the output folder)")
    run(command, progress=progress, output=output, **options)
    return _summary(Path(output) / summary_name)


def phantom(output, progress=None, **options):
    """Generates a phantom dataset (physreg phantom): labels, images, landmarks, partial
    surfaces and ground-truth deformations from an independent model; returns its manifest."""
    return _command_with_folder("phantom", output, "manifest.json", progress, options)


def simulate(case, output=None, progress=None, **options):
    """Runs a simulation case file (YAML; docs/simulate.md); output overrides the case's folder.
    Returns summary.json (max displacement mm, solver statistics, seconds)."""
    if output is None:  # checked before the simulation runs, not after
        raise TypeError("simulate() needs output= (the output folder; it overrides the case file's)")
    run("simulate", case, progress=progress, output=output, **options)
    return _summary(Path(output) / "summary.json")


def register_compression(output, progress=None, **options):
    """Predicts a phantom compression with the heterogeneous hexahedral model (paper 000):
    dataset=, state=, optional parameters=, variant=, …; returns summary.json (TRE in mm)."""
    return _command_with_folder("register-compression", output, "summary.json", progress, options)


def register_surface(output, progress=None, **options):
    """Registers a tetrahedral liver model to a partial intra-operative surface (paper 001):
    dataset=/state=/visible= or labels=/surface=/model= with cloud=, …; returns summary.json
    (TRE, Hausdorff distance in mm, per method)."""
    return _command_with_folder("register-surface", output, "summary.json", progress, options)


def register_images(output, progress=None, **options):
    """Segmentation-driven biomechanical registration with estimated moduli (paper 002) and the
    rigid, Demons and B-spline baselines: dataset= or fixed=/fixed_labels=/moving=/
    moving_labels=, …; returns summary.json (Dice, surface distance, TRE per method)."""
    return _command_with_folder("register-images", output, "summary.json", progress, options)


def evaluate(predicted, truth, output, progress=None, **options):
    """TRE of one or more predicted landmark files against the truth (matched by name);
    writes tre.csv/tre.json/tre.png into output and returns tre.json."""
    if isinstance(predicted, (str, os.PathLike)):
        predicted = [predicted]
    return _command_with_folder("evaluate", output, "tre.json", progress,
                                dict(options, predicted=list(predicted), truth=truth))


def enrich_build(output, progress=None, **options):
    """Builds the coarse-to-fine detail enrichment database (paper 000): dataset=, …;
    output is the database file. Returns None."""
    run("enrich build", progress=progress, output=output, **options)


def enrich_apply(output, progress=None, **options):
    """Predicts a compression with the coarse model plus the enrichment database:
    database=, dataset=, state=, …; returns summary.json."""
    return _command_with_folder("enrich apply", output, "summary.json", progress, options)
