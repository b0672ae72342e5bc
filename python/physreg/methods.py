# SPDX-License-Identifier: GPL-3.0-or-later
"""One method of a mode, alone, with its own defaults: not the mode's whole pipeline.

- ``register(model, observation)``: one shared ``Model`` moved by the solver the observation needs
  (a Tool: TLED; a Cloud: paper 001's pair forces; a Segmentation: paper 002's linear elasticity),
  without supports chosen by the data, baselines, safeguard or predicted error.
- ``register_surface_cloud(surface_model, points, …)``: paper 001's biomechanical method alone
  (``register-surface --method biomechanical`` under one given support).

A mode's whole pipeline, as the program runs it, is ``physreg.register_partial_surface``,
``physreg.register_image_pair`` or ``physreg.predict_compression``. The same functions are also
reachable as ``physreg.<name>`` (kept for scripts written against 0.1).
"""
from ._physreg import register, register_surface_cloud  # noqa: F401

__all__ = ["register", "register_surface_cloud"]
