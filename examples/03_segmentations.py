#!/usr/bin/python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Register one segmentation to another from Python, with the label maps alone (paper 002's mode).

A user's pair is two label files (e.g. an MR gland and a TRUS gland) and, to score it, the same
landmarks picked in both. Here the pair is made on the spot so the example runs anywhere: an
ellipsoid gland with a lesion, and the same gland pressed from one side (flattened 15 % along y,
widened to keep its volume) and shifted by (6, -4, 3) mm, as a probe would leave it.

    PYTHONPATH=build/python /usr/bin/python3 examples/03_segmentations.py [OUT_DIR]

With files instead of arrays: `physreg.read_labels(path)` gives the same (array, geometry) pairs, and
`physreg register-images --moving-labels M --fixed-labels F --baselines labels -o OUT` is the command.
"""
import sys

import numpy as np

import physreg


def gland(scale_y, shift):
    """uint16 [z, y, x] labels on 1.5 mm voxels: 1 the gland (semi-axes 24, 16, 12 mm), 2 a lesion."""
    geometry = physreg.ImageGeometry(origin=[0.0, 0.0, 0.0], spacing=[1.5, 1.5, 1.5])
    z, y, x = np.indices((40, 48, 60)).astype(float) * 1.5
    centre = np.array([45.0, 36.0, 30.0]) + shift
    sx = 1.0 / np.sqrt(scale_y)  # keep the volume: what the probe flattens, the sides take
    px, py, pz = (x - centre[0]) / sx, (y - centre[1]) / scale_y, (z - centre[2])
    labels = np.zeros(x.shape, np.uint16)
    labels[(px / 24) ** 2 + (py / 16) ** 2 + (pz / 12) ** 2 < 1] = 1
    labels[(px - 8) ** 2 + (py - 4) ** 2 + (pz - 2) ** 2 < 36] = 2
    lesion_centre = centre + np.array([8 * sx, 4 * scale_y, 2.0])
    return labels, geometry, lesion_centre


# --- the registration
moving, gm, lesion_moving = gland(1.0, np.zeros(3))
fixed, gf, lesion_fixed = gland(0.85, np.array([6.0, -4.0, 3.0]))

# None for the images: a label-to-label pair (the label baselines run, not the intensity ones).
pair = physreg.ImagePair(None, fixed, gf, None, moving, gm,
                         landmarks_fixed={"lesion": tuple(lesion_fixed)}, landmarks_moving={"lesion": tuple(lesion_moving)})
result = physreg.register_images(pair, baselines="labels", cell_size=4.0)

s = result.summary
print(f"initial alignment: {s['initial_alignment']['decision']}")
for name in ("at_rest", "initial_alignment", "biomechanical", "rigid_labels", "demons_labels", "bspline_labels"):
    m = s["methods"][name]
    print(f"{name:18s} lesion error {m['tre']['all']['mean_mm']:5.2f} mm   Dice " +
          ", ".join(f"label {k}: {v:.3f}" for k, v in m["dice"].items()))
print(s["biomechanical_against_baselines"]["reading"])

field, geometry = result.field()  # float32 [z, y, x, 3], mm: fixed → moving, as ITK's displacement fields
print(f"field {field.shape} on a {geometry.spacing[0]} mm grid; largest displacement {np.linalg.norm(field, axis=-1).max():.1f} mm")
if len(sys.argv) > 1:
    physreg.write_labels(f"{sys.argv[1]}/warped_labels.nii.gz", *result.warped_labels)

# --- what the example promises (ctest runs it): the lesion lands within 2 mm, the gland overlaps well.
bio = s["methods"]["biomechanical"]
assert bio["tre"]["all"]["mean_mm"] < 2.0, bio["tre"]
assert bio["dice"]["1"] > 0.9, bio["dice"]
assert s["intensities"] is False
