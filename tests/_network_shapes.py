"""Shapes shared by the network tests."""

import numpy as np

from thirdbody.shapes import Potato, Wave


def two_bumps() -> Potato:
    """An ellipsoid (1, 0.6, 0.6) mm whose radius is modulated by 1 − 0.12 cos(2π d_x): two
    equal bumps on its upper (and lower) side at body x ≈ ±0.3 mm, 0.64 mm high, with a dip to
    0.53 mm between them. Symmetric in x, y and z, so its centroid is the wave centre."""
    return Potato((1e-3, 0.6e-3, 0.6e-3), [Wave(0.12, 2 * np.pi, 0.0, -np.pi / 2)])
