"""Make the bundled asymmetric grain, ``src/thirdbody/examples/grain.stl`` (millimetres).

An ellipsoid of semi-axes 0.9 x 0.6 x 0.45 mm whose radius is modulated by four sine waves
running along random directions in 3-D (not in a symmetry plane, unlike
:class:`thirdbody.shapes.Potato`), so the grain has no plane of symmetry: tilted, it is pushed
to turn about an axis that changes as it turns. The vertices of an icosphere (4 levels, 5120
triangles) are moved radially onto that surface; the configuration ``grain.toml`` refines it
with Loop subdivision when it is read.

    python examples/make_grain_mesh.py [--out src/thirdbody/examples/grain.stl]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SEMI_AXES_MM = np.array([0.9, 0.6, 0.45])
SEED = 11


def radius(directions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Radius (mm) of the grain along unit ``directions`` (n, 3) from its centre."""
    waves = [(0.06, rng.uniform(2.5, 4.5), v / np.linalg.norm(v), rng.uniform(0, 2 * np.pi))
             for v in rng.normal(size=(4, 3))]
    r = 1.0 / np.sqrt(np.sum((directions / SEMI_AXES_MM) ** 2, axis=-1))
    return r * (1.0 + sum(a * np.sin(k * directions @ e + phase) for a, k, e, phase in waves))


def main(argv: list[str] | None = None) -> Path:
    import trimesh

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent.parent
                        / "src" / "thirdbody" / "examples" / "grain.stl")
    args = parser.parse_args(argv)
    ico = trimesh.creation.icosphere(subdivisions=4)
    d = np.asarray(ico.vertices, dtype=float)
    vertices = d * radius(d, np.random.default_rng(SEED))[:, None]
    mesh = trimesh.Trimesh(vertices, ico.faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0
    mesh.export(args.out, file_type="stl")
    print(f"{args.out}: {len(mesh.faces)} triangles, volume {mesh.volume:.4f} mm³")
    return args.out


if __name__ == "__main__":
    main()
