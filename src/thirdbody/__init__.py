"""thirdbody: a deformable third-body particle between two rigid plates, by FFT-accelerated BEM.

Public API::

    Material(E, nu)                     elastic constants (Pa, -)
    Grid(n, spacing)                    a window of cells (m)
    solve_normal(gap, grid, material, force=... | approach=...)   -> NormalContact
    solve_tangential(normal, mu, force=... | shift=..., previous=...) -> TangentialContact
    reference.hertz, reference.mindlin  analytic solutions to check runs against
    citations()                         the papers behind the methods used
    Particle(shape, material, orientation_deg, tilt_axis_deg, yaw_deg | quaternion=...)
    orientation.tilt, orientation.decompose   3-D orientations (scipy Rotation)
    Plates(mu_up, mu_low)
    Simulation(particle, plates, LinearRamp(stop=F, steps=n)).run() -> xarray.Dataset
    Layer([PlacedParticle(particle, (x, y)), ...]), Layer.random(...)   many particles
    Simulation(layer, plates, load).run()  -> the same dataset form, along (step, particle)
    Simulation(layer, plates, Slide(force=F, distance=s), mu_pp=...)   sliding plates
    particle_view(ds, i)                one particle's results (no particle dimension)
    schema.VARIABLES                    every output variable: dims, units, long name
"""

# first: for the thirdbody command only, Ctrl-C during these imports exits 130 quietly (the
# guard is installed as the module is imported)
from . import _interrupt  # noqa: F401, I001

from . import orientation, schema
from ._citations import citations
from ._version import __version__
from .bem import (
    ContactAtEdgeError,
    ConvergenceError,
    FrictionLimitError,
    Grid,
    NormalContact,
    TangentialContact,
    set_workers,
    solve_normal,
    solve_tangential,
)
from .layer import Layer, LayerError, PlacedParticle
from .loading import ForceTable, GapRamp, HoldThenRamp, LinearRamp, Slide
from .material import Material
from .particle import Particle, Plates
from .records import particle_view
from .simulation import Simulation, SimulationError, SimulationStoppedWarning

__all__ = [
    "ContactAtEdgeError",
    "ConvergenceError",
    "ForceTable",
    "FrictionLimitError",
    "GapRamp",
    "Grid",
    "HoldThenRamp",
    "Layer",
    "LayerError",
    "LinearRamp",
    "Material",
    "NormalContact",
    "Particle",
    "PlacedParticle",
    "Plates",
    "Simulation",
    "SimulationError",
    "SimulationStoppedWarning",
    "Slide",
    "TangentialContact",
    "__version__",
    "citations",
    "orientation",
    "particle_view",
    "schema",
    "set_workers",
    "solve_normal",
    "solve_tangential",
]
