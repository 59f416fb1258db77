"""Particle geometry: shapes seen through vertical rays by the two plates.

Geometry only (no solver imports). Conventions (docs/methods/design.md §2): x horizontal in the
plane of rotation, y the rotation axis, z up; orientation θ is a rotation about +y (right-hand
rule), radians here; a body-frame point (x, y, z) sits at world (x cosθ + z sinθ, y, −x sinθ + z
cosθ); every shape has its volume centroid at the body origin; lengths in metres.

* :class:`Shape` — the interface: :meth:`~Shape.surfaces`, :meth:`~Shape.gap_lower`,
  :meth:`~Shape.gap_upper`, extreme points, :meth:`~Shape.height`, :meth:`~Shape.mirrored`.
* :class:`Sphere`, :class:`Ellipsoid` — closed forms.
* :class:`Potato` — ellipsoid modulated by smooth sine waves (the paper's section 3 particle).
* :class:`MeshShape` — closed triangle meshes through trimesh (refine them far below the
  contact cell size: facets carry no curvature).
"""

from thirdbody.shapes.base import Shape, rotate_to_body, rotate_to_world
from thirdbody.shapes.ellipsoid import Ellipsoid, Sphere
from thirdbody.shapes.mesh import MeshShape
from thirdbody.shapes.potato import MAX_TOTAL_AMPLITUDE, Potato, Wave, draw_waves

__all__ = [
    "MAX_TOTAL_AMPLITUDE",
    "Ellipsoid",
    "MeshShape",
    "Potato",
    "Shape",
    "Sphere",
    "Wave",
    "draw_waves",
    "rotate_to_body",
    "rotate_to_world",
]
