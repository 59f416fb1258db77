"""Dense layers: particles touching particles (docs/methods/design.md §3c).

The building block is one particle-particle contact resolved by the boundary-element method in
its own frame:

* :class:`Body` — a particle's shape, material and pose (rotation, centroid position);
* :func:`candidate_pairs` — the broad phase: pairs whose bounding spheres overlap (KD-tree,
  optionally periodic in x and y);
* :func:`closest_approach` — the narrow phase: common normal, closest points and signed
  separation of two bodies, from vertical ray casting only;
* :func:`solve_contact` — the contact: gap over every cell that can touch, normal solve in force
  or approach control, incremental partial slip in the tangent plane with the history carried
  as the frame turns; a frozen :class:`PairContact` with forces, wrenches and the half-space
  diagnostics (:class:`HalfSpaceWarning`).
"""

from .body import Body
from .broad import CandidatePairs, candidate_pairs
from .contact import HALF_SPACE_LIMIT, HalfSpaceWarning, PairContact, solve_contact
from .frame import contact_frame
from .narrow import Approach, closest_approach

__all__ = [
    "HALF_SPACE_LIMIT",
    "Approach",
    "Body",
    "CandidatePairs",
    "HalfSpaceWarning",
    "PairContact",
    "candidate_pairs",
    "closest_approach",
    "contact_frame",
    "solve_contact",
]
