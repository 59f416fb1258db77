"""Dense layers: particles touching particles (DESIGN.md §3c).

* :class:`Body` — a particle's shape, material and pose (rotation, centroid position);
* :func:`candidate_pairs` — the broad phase: pairs whose bounding spheres overlap (KD-tree,
  optionally periodic in x and y).
"""

from .body import Body
from .broad import CandidatePairs, candidate_pairs

__all__ = ["Body", "CandidatePairs", "candidate_pairs"]
