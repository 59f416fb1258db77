"""``thirdbody validate``: the analytic checks at a quick resolution (computed vs analytic)."""

from __future__ import annotations

import math

import typer


def validate() -> None:
    """Run the analytic checks at a quick resolution and print computed vs analytic values."""
    rows = _validation_rows()
    width = max(len(r[0]) for r in rows)
    typer.echo(f"{'check':{width}s}  {'computed':>12s}  {'analytic':>12s}  {'error':>9s}  "
               f"{'tolerance':>9s}  ok")
    bad = 0
    for name, computed, analytic, tol in rows:
        err = abs(computed / analytic - 1) if analytic else abs(computed)
        ok = err <= tol
        bad += not ok
        typer.echo(f"{name:{width}s}  {computed:12.6g}  {analytic:12.6g}  {err:9.2e}  "
                   f"{tol:9.1e}  {'yes' if ok else 'NO'}")
    if bad:
        typer.echo(f"{bad} check(s) out of tolerance", err=True)
        raise typer.Exit(1)


def _validation_rows() -> list[tuple[str, float, float, float]]:
    import numpy as np

    import thirdbody as tb
    from thirdbody import rigid
    from thirdbody.reference import hertz, mindlin
    from thirdbody.shapes import Ellipsoid

    rows = []
    mat = tb.Material(210e9, 0.3)
    L, W, R = 1e-3, 1.0, 4 * mat.E_star * (1e-3 / 8) ** 3 / 3
    grid = tb.Grid(128, L / 128)
    normal = tb.solve_normal(grid.paraboloid(R), grid, mat, force=W)
    ref = hertz.sphere(W, R, mat.E_star)
    rows += [("Hertz sphere 128²: approach (m)", normal.approach, ref.approach, 1e-3),
             ("Hertz sphere 128²: peak pressure (Pa)", float(normal.pressure.max()),
              ref.peak_pressure, 3e-3)]
    mu = 0.5
    t = tb.solve_tangential(normal, mu, force=0.5 * mu * W)
    cm = mindlin.cattaneo_mindlin(0.5 * mu * W, W, mu, R, mat.E, mat.nu)
    rows += [("Cattaneo-Mindlin Q=0.5μP: shift (m)", float(t.shift[0]), cm.shift, 1e-2),
             ("Cattaneo-Mindlin Q=0.5μP: stick radius (m)",
              math.sqrt(t.stick_area / math.pi), cm.stick_radius, 0.05)]
    q_star = 0.8 * mu * W
    loaded = tb.solve_tangential(normal, mu, force=q_star)
    unloaded = tb.solve_tangential(normal, mu, force=0.0, previous=loaded)
    md = mindlin.mindlin_deresiewicz_unloading(0.0, q_star, W, mu, R, mat.E, mat.nu)
    rows.append(("Mindlin-Deresiewicz unloaded to 0: shift (m)", float(unloaded.shift[0]),
                 md.shift, 2e-2))
    A, B, C = 1e-3, 0.8e-3, 0.6e-3
    sim = tb.Simulation(tb.Particle(Ellipsoid((A, B, C)), mat, 20.0), tb.Plates(0.6),
                        tb.ForceTable([0.5]), resolution=400, maps_every=0)
    ds = tb.particle_view(sim.run(), 0)
    rows.append(("rigid criterion: steel ellipsoid θ=20°, |F'_x|/F_N",
                 float(np.abs(ds.tangential_force.sel(component="x")[0]) / ds.normal_force[0]),
                 rigid.ellipsoid_xi(A, C, math.radians(20.0)), 2e-3))
    sim = tb.Simulation(tb.Particle(Ellipsoid((A, B, C)), mat, 20.0), tb.Plates(0.3),
                        tb.ForceTable([1.0]), resolution=100, maps_every=0)
    ds = tb.particle_view(sim.run(), 0)
    rows.append(("rigid equilibrium angle, μ=0.3 (deg)",
                 float(ds.orientation.sel(component="y")[0]),
                 math.degrees(rigid.ellipsoid_equilibrium_angle(A, C, math.radians(20.0), 0.3)),
                 5e-3))
    return rows
