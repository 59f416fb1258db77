"""A third-body layer: many particles between the same two plates.

:mod:`~thirdbody.layer.placement` places them (:class:`Layer`, :meth:`Layer.random`, the overlap
check); :mod:`~thirdbody.layer.sharing` shares the plates' load among them.
"""

from .placement import Layer, LayerError, PlacedParticle, first_overlap

__all__ = ["Layer", "LayerError", "PlacedParticle", "first_overlap"]
