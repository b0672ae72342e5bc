#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Register an organ model to a partial intra-operative surface from Python (paper 001's mode).

A user has the organ segmented before the operation (a label file) and, during it, a point cloud over
the part of the surface a camera or a tracked probe saw. Here both are made on the spot so the
example runs anywhere: a flattened ellipsoid organ (2 mm voxels), pressed from above by a tool
(a smooth dent 14 mm deep, fading with depth: a made-up deformation, not physreg's own model), and
a cloud of 400 points over the upper half of the pressed surface with 0.3 mm noise.

    PYTHONPATH=build/python /usr/bin/python3 examples/02_partial_surface.py [OUT_DIR]

With files instead of arrays: `physreg.read_labels(path)` for the label map and
`physreg.read_surface(path)` or numpy for the cloud; the command is
`physreg register-surface --labels L.nii.gz --cloud C.ply --landmarks T.csv -o OUT`.
"""
import sys

import numpy as np

import physreg

# --- the organ before the operation: a label map, uint16 [z, y, x], and its geometry (mm, LPS)
geometry = physreg.ImageGeometry(origin=[-100.0, -70.0, -56.0], spacing=[2.0, 2.0, 2.0])
z, y, x = np.indices((57, 71, 101)).astype(float) * 2.0 + np.array([-56.0, -70.0, -100.0])[:, None, None, None]
# A right lobe (an ellipsoid) and a smaller left lobe beside it: a shape without symmetries, as an
# organ is (a cloud over an ellipsoid fits it turned as well as upright, and the pose is undetermined).
labels = (((x + 15) / 70) ** 2 + (y / 55) ** 2 + (z / 42) ** 2 < 1) | (((x - 50) / 40) ** 2 + ((y + 10) / 35) ** 2 + ((z - 10) / 25) ** 2 < 1)
labels = labels.astype(np.uint16)


def pressed(points):
    """The tool's push, mm: a dent along -y centred at (20, 55, 5), radius ~25 mm, 14 mm deep at the
    surface, halving every 28 mm of depth."""
    p = np.atleast_2d(points)
    u = np.zeros_like(p)
    u[:, 1] = -14.0 * np.exp(-((p[:, 0] - 20) ** 2 + (p[:, 2] - 5) ** 2) / (2 * 25.0 ** 2)) * 0.5 ** ((55 - p[:, 1]) / 28)
    return p + u


# --- the registration
model = physreg.SurfaceModel.from_labels(labels, geometry, cell_size_mm=9.0)
rest = np.array(model.mesh.nodes)
surface_nodes = np.unique(model.surface_triangles)
upper = surface_nodes[rest[surface_nodes, 1] > 10.0]  # what the camera saw
rng = np.random.default_rng(7)
seen = pressed(rest[rng.choice(upper, size=min(400, len(upper)), replace=False)])
cloud = seen + rng.normal(scale=0.3, size=seen.shape)

target = np.array([18.0, 38.0, 4.0])  # a lesion 17 mm under the pressed spot
case = physreg.PartialSurfaceCase(model, cloud, landmarks={"lesion": tuple(target)}, truth={"lesion": tuple(pressed(target)[0])})
result = physreg.register_surface(case, noise=0.3)

s = result.summary
print(f"answer written: {s['safeguard']['answer']} ({s['safeguard']['statement']})")
for name in ("at_rest", "rigid", "adjoint"):
    m = s["methods"][name]
    print(f"{name:8s} lesion error {m['tre']['all']['mean_mm']:5.2f} mm   cloud to model {m['cloud_to_model_mm']['mean']:5.2f} mm")
print(s["predicted_error"]["statement"])
field, field_geometry = result.field(case)  # float32 [z, y, x, 3], mm, over the model
print(f"field {field.shape} on a {field_geometry.spacing[0]} mm grid; nodal displacement {result.displacement().shape}")
if len(sys.argv) > 1:
    physreg.write_displacement_field(f"{sys.argv[1]}/displacement.nii.gz", field, field_geometry)

# --- what the example promises (ctest runs it): the lesion moves with the organ, closer than at rest
bio = s["methods"][s["safeguard"]["answer"]]["tre"]["all"]["mean_mm"]
assert bio < 0.5 * s["methods"]["at_rest"]["tre"]["all"]["mean_mm"], s["methods"]
assert s["predicted_error"]["mean_mm"] > 0
