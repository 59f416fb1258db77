"""Dense layers: particles touching particles (DESIGN.md §3c).

* :class:`Body` — a particle's shape, material and pose (rotation, centroid position);
* :func:`candidate_pairs` — the broad phase: pairs whose bounding spheres overlap (KD-tree,
  optionally periodic in x and y);
* :func:`closest_approach` — the narrow phase: common normal, closest points and signed
  separation of two bodies, from vertical ray casting only.
"""

from .body import Body
from .broad import CandidatePairs, candidate_pairs
from .frame import contact_frame
from .narrow import Approach, closest_approach

__all__ = ["Approach", "Body", "CandidatePairs", "candidate_pairs", "closest_approach",
           "contact_frame"]
