# SPDX-License-Identifier: GPL-3.0-or-later
"""The physreg program's commands, run in this process, each writing its output folder as the
program does and returning the summary it wrote (a dict).

These are the command line's twins: ``commands.register_surface(out, labels=…, cloud=…)`` is
``physreg register-surface --labels … --cloud … -o out``. For a registration in memory (numpy
arrays in, a result object out) use the mode's entry point instead: ``physreg.register_partial_surface``,
``physreg.register_image_pair``, ``physreg.predict_compression`` or ``physreg.serve``. The same
functions are also reachable as ``physreg.<name>`` (kept for scripts written against 0.1).
"""
from ._commands import (  # noqa: F401
    enrich_apply,
    enrich_build,
    evaluate,
    phantom,
    register_compression,
    register_images,
    register_surface,
    run,
    simulate,
)

__all__ = ["enrich_apply", "enrich_build", "evaluate", "phantom", "register_compression", "register_images", "register_surface", "run",
           "simulate"]
