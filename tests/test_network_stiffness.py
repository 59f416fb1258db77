"""The contact models' tangential laws evaluated for many contacts at once
(:class:`thirdbody.network.stiffness.ModelStack`) against the law written out for one contact
at a time (the form the Newton step used before it was vectorised, kept here as the reference)
on random contacts in every state: stick cells inside and beyond the cone, sliding on along
the slip, reversed back to stick and beyond, frictionless."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from thirdbody.network import stiffness
from thirdbody.network.stiffness import ContactModel, ModelStack, skew

I3 = np.eye(3)


def reference_law(model: ContactModel, ds: np.ndarray, dN: float):
    """(stiffness, g, offset, slide) of one contact's law at (ds, dN): the stiffness module's
    docstring, branch by branch."""
    n = model.normal
    P = I3 - np.outer(n, n)
    T = model.tangential_force
    zero = np.zeros(3)
    if model.mu <= 0 or model.k_stick <= 0:
        return np.zeros((3, 3)), zero, zero, True
    limit = model.mu * max(model.normal_force + dN, 0.0)
    if model.sliding and float(ds @ model.slip_direction) >= 0:
        d = model.slip_direction
        return (model.k_across * (P - np.outer(d, d)), T / model.normal_force, zero, True)
    loading = not model.sliding and (stiffness._TANGENT_BOTH_WAYS or float(ds @ T) > 0)
    k = model.k_loading if loading else model.k_stick
    g = zero
    size_T = float(np.linalg.norm(T))
    if not model.sliding and size_T > 0:
        # Cattaneo-Mindlin: dT/dN = μ [q − u (1 − q)^(1/3)] along T, u = 1 − (1 − q)^(2/3)
        q = min(size_T / (model.mu * model.normal_force), 1.0)
        u = 1.0 - (1.0 - q) ** (2.0 / 3.0)
        g = model.mu * (q - u * (1.0 - q) ** (1.0 / 3.0)) * T / size_T
    back = model.slipped if model.sliding else zero
    trial = T + k * (ds + back) + g * dN
    size = float(np.linalg.norm(trial))
    if size <= limit or size == 0:
        return k * P, g, k * back, False
    d = trial / size
    across = model.mu * model.normal_force / size * k * (P - np.outer(d, d))
    value = model.mu * model.normal_force * d - across @ ds
    return across, model.mu * d, value - T, True


def random_contacts(rng, count: int) -> list[ContactModel]:
    """Contacts with random normals, forces (|T| up to 0.95 μN), stick shares, curvatures;
    a third sliding, some frictionless."""
    models = []
    for m in range(count):
        n = rng.standard_normal(3)
        n /= np.linalg.norm(n)
        P = I3 - np.outer(n, n)
        N = rng.uniform(0.1, 2.0)
        mu = 0.0 if m % 11 == 0 else rng.uniform(0.1, 0.6)
        T = P @ rng.standard_normal(3)
        T *= rng.uniform(0.0, 0.95) * mu * N / max(np.linalg.norm(T), 1e-30)
        sliding = mu > 0 and m % 3 == 1
        area = rng.uniform(1e-8, 4e-8)
        K = np.diag([1e3, 1e3, 0.0])
        model = ContactModel.of(
            normal=n, point=rng.standard_normal(3) * 1e-3, centre_a=rng.standard_normal(3) * 1e-3,
            centre_b=rng.standard_normal(3) * 1e-3, normal_force=N, tangential_force=T,
            twist_moment=rng.standard_normal() * 1e-6, approach=rng.uniform(1e-7, 1e-6),
            area=area, stick_area=rng.uniform(0.05, 1.0) * area, mu=mu,
            slip=rng.standard_normal(3) * 1e-7, compliance=5e-9, torsion=2.6e-9,
            curvature_a=K, curvature_b=K, sliding=sliding)
        if m % 2:
            model = model.stepping(mid_a=rng.standard_normal(3) * 1e-3,
                                   mid_b=rng.standard_normal(3) * 1e-3,
                                   turn_a=rng.standard_normal(3) * 1e-3,
                                   turn_b=rng.standard_normal(3) * 1e-3, fraction=0.7)
        models.append(model)
    return models


def _central_differences(function) -> np.ndarray:
    """Central differences of ``function`` (12 motions of two bodies: translations of a in m,
    rotations of a in rad, then of b) column by column: steps of 1 nm and 1 µrad."""
    steps = np.array([1e-9] * 3 + [1e-6] * 3 + [1e-9] * 3 + [1e-6] * 3)
    columns = []
    for j in range(12):
        e = np.zeros(12)
        e[j] = steps[j]
        columns.append((np.asarray(function(e)) - np.asarray(function(-e))) / (2 * steps[j]))
    return np.stack(columns, axis=-1)


@pytest.mark.parametrize("both_ways", [True, False])
def test_the_stacked_laws_are_the_per_contact_laws_in_every_state(monkeypatch, both_ways):
    monkeypatch.setattr(stiffness, "_TANGENT_BOTH_WAYS", both_ways)
    rng = np.random.default_rng(7)
    models = random_contacts(rng, 300)
    stack = ModelStack(models)
    slip_scale = np.array([m.mu * m.normal_force / max(m.k_stick, 1e-30) for m in models])
    ds = np.array([(np.eye(3) - np.outer(m.normal, m.normal)) @ rng.standard_normal(3)
                   for m in models]) * slip_scale[:, None] * rng.uniform(0.0, 2.0, (300, 1))
    # a sliding contact reverses (against its slip) or goes on along it
    for k, m in enumerate(models):
        if m.sliding and k % 2:
            ds[k] = -ds[k] if ds[k] @ m.slip_direction > 0 else ds[k]
    dN = stack.normal_force * rng.uniform(-1.2, 1.0, 300)
    laws = stack.laws(ds, dN)
    states = {"frictionless": 0, "stick": 0, "slide": 0, "along": 0, "back stick": 0,
              "back slide": 0}
    for k, m in enumerate(models):
        S, g, offset, slide = reference_law(m, ds[k], dN[k])
        np.testing.assert_allclose(laws.stiffness[k], S, rtol=1e-12, atol=1e-12 * np.abs(S).max())
        np.testing.assert_allclose(laws.g[k], g, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(laws.offset[k], offset, rtol=1e-12,
                                   atol=1e-12 * m.mu * m.normal_force)
        assert laws.slide[k] == slide
        if m.mu == 0:
            states["frictionless"] += 1
        elif not m.sliding:
            states["slide" if slide else "stick"] += 1
        elif ds[k] @ m.slip_direction >= 0:
            states["along"] += 1
        else:
            states["back slide" if slide else "back stick"] += 1
    assert min(states.values()) >= 5, states
    # the start of a Newton step: the elastic predictor from the start of the step
    elastic = stack.elastic()
    for k, m in enumerate(models):
        back = m.slipped if m.sliding else np.zeros(3)
        P = I3 - np.outer(m.normal, m.normal)
        np.testing.assert_allclose(elastic.stiffness[k], m.k_stick * P, rtol=1e-15)
        np.testing.assert_allclose(elastic.offset[k], m.k_stick * back, rtol=1e-15)
    assert not elastic.slide.any() and not elastic.g.any()


def test_the_stacked_law_blocks_are_the_forces_and_moments_of_the_laws():
    """The blocks of dT on a and b are (dT, r_a × dT) and −(dT, r_b × dT), dT = S ds/dx +
    g k_n dδ/dx, and the offsets' wrenches (c, r_a × c) and −(c, r_b × c)."""
    rng = np.random.default_rng(3)
    models = random_contacts(rng, 40)
    stack = ModelStack(models)
    ds = rng.standard_normal((40, 3)) * 1e-7
    laws = stack.laws(ds, np.zeros(40))
    on_a, on_b, c_a, c_b = stack.law_blocks(laws)
    for k, m in enumerate(models):
        ra, rb = m.point - m.centre_a, m.point - m.centre_b
        dT = laws.stiffness[k] @ stack.tangential_rows[k] + \
            np.outer(laws.g[k], m.k_normal * stack.approach_rows[k])
        np.testing.assert_allclose(on_a[k], np.vstack([dT, skew(ra) @ dT]), rtol=1e-13,
                                   atol=1e-13 * np.abs(on_a[k]).max())
        np.testing.assert_allclose(on_b[k], -np.vstack([dT, skew(rb) @ dT]), rtol=1e-13,
                                   atol=1e-13 * np.abs(on_b[k]).max())
        c = laws.offset[k]
        np.testing.assert_allclose(c_a[k], np.concatenate([c, np.cross(ra, c)]), rtol=1e-13,
                                   atol=1e-13 * np.abs(c_a[k]).max() + 1e-300)
        np.testing.assert_allclose(c_b[k], -np.concatenate([c, np.cross(rb, c)]), rtol=1e-13,
                                   atol=1e-13 * np.abs(c_b[k]).max() + 1e-300)


def test_the_stacked_base_blocks_of_two_spheres_are_the_derivatives_of_their_wrench():
    """Two touching spheres (radii R_a, R_b, centres along a random normal n) carry
    F_a = −N n with N = N₀ + k_n δ, δ = R_a + R_b − |c_b − c_a|, at x_p = c_a + R_a n, and the
    twist m n with m = k_w n·(φ_b − φ_a): their moments about the centres vanish at any pose
    but for the twist (x_p − c_a and x_p − c_b lie along n). The base blocks (contact point
    migrating over both curved surfaces, the normal turning) and the approach row against
    central differences of that wrench under every rigid motion."""
    rng = np.random.default_rng(11)
    Ra, Rb, N0, kn = 1.0e-3, 0.6e-3, 0.8, 2.0e6
    n0 = rng.standard_normal(3)
    n0 /= np.linalg.norm(n0)
    ca0 = rng.standard_normal(3) * 1e-3
    cb0 = ca0 + (Ra + Rb) * n0
    P = I3 - np.outer(n0, n0)
    area = 2e-9
    model = ContactModel.of(
        normal=n0, point=ca0 + Ra * n0, centre_a=ca0, centre_b=cb0, normal_force=N0,
        tangential_force=np.zeros(3), twist_moment=0.0, approach=1.5 * N0 / kn, area=area,
        stick_area=area, mu=0.3, slip=np.zeros(3), compliance=5e-9, torsion=2.6e-9,
        curvature_a=P / Ra, curvature_b=P / Rb, sliding=False)
    stack = ModelStack([model])
    k_twist = 16.0 / 3.0 * (area / np.pi) ** 1.5 / 2.6e-9

    def wrenches(x):
        ca, pa, cb, pb = x[:3] + ca0, x[3:6], x[6:9] + cb0, x[9:]
        d = cb - ca
        n = d / np.linalg.norm(d)
        N = N0 + kn * (Ra + Rb - np.linalg.norm(d))
        f = -N * n
        m = k_twist * (n0 @ (pb - pa)) * n
        xp = ca + Ra * n
        return (np.concatenate([f, np.cross(xp - ca, f) + m]),
                np.concatenate([-f, -np.cross(xp - cb, f) - m]),
                Ra + Rb - np.linalg.norm(d))

    fd = _central_differences(lambda e: np.concatenate([*wrenches(e)[:2], [wrenches(e)[2]]]))
    fd_a, fd_b, fd_delta = fd[:6], fd[6:12], fd[12]
    # absolute tolerances by quadrant: force or moment rows, translation or rotation columns
    rotation = np.repeat([False, True, False, True], 3)
    atol = 1e-6 * np.where(rotation[None, :], np.array([[N0]] * 3 + [[N0 * Ra]] * 3),
                           np.array([[kn]] * 3 + [[N0]] * 3))
    for block, fd in ((stack.base_a[0], fd_a), (stack.base_b[0], fd_b)):
        assert (np.abs(block - fd) <= atol + 1e-5 * np.abs(fd)).all(), block - fd
    assert np.abs(fd_a[3:, 9:]).max() > 1e3 * atol[3:, 9:].max()        # the twist is seen
    np.testing.assert_allclose(stack.approach_rows[0], fd_delta, rtol=1e-6, atol=1e-9)


def test_a_solved_contacts_model_holds_the_textbook_stiffnesses():
    """Two bodies of different materials (E = 1 and 3 GPa, ν = 0.3 and 0.2): Hertz's
    k_n = 3N/(2δ), Mindlin's k₀ = 8aG* with 1/G* = (2 − ν₁)/G₁ + (2 − ν₂)/G₂ (Johnson 1985,
    §7.2) times c/a = √(A_stick/A) for loading, Lubkin's torsion (16/3) a³ G' with
    1/G' = 1/G₁ + 1/G₂ times (c/a)³, a = √(A/π); a sliding contact slides along its slip's
    tangential part, turning with μN/|slip| across it, capped at k₀."""
    G1, G2 = 1e9 / (2 * 1.3), 3e9 / (2 * 1.2)
    nu1, nu2 = 0.3, 0.2
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    P = I3 - np.outer(n, n)
    N, delta, area, stick, mu = 2.5, 3e-7, 4e-8, 1e-8, 0.4
    a = math.sqrt(area / math.pi)
    common = dict(normal=n, point=np.zeros(3), centre_a=-n * 1e-3, centre_b=n * 1e-3,
                  normal_force=N, tangential_force=P @ np.array([0.1, -0.2, 0.3]),
                  twist_moment=1e-6, approach=delta, area=area, stick_area=stick, mu=mu,
                  compliance=(2 - nu1) / G1 + (2 - nu2) / G2, torsion=1 / G1 + 1 / G2,
                  curvature_a=P * 1e3, curvature_b=P * 2e3)
    k0 = 8 * a / ((2 - nu1) / G1 + (2 - nu2) / G2)
    share = 0.5                                     # √(1e-8 / 4e-8)
    stuck = ContactModel.of(slip=np.zeros(3), sliding=False, **common)
    assert stuck.k_normal == pytest.approx(1.5 * N / delta, rel=1e-14)
    assert stuck.k_stick == pytest.approx(k0, rel=1e-14)
    assert stuck.k_loading == pytest.approx(share * k0, rel=1e-14)
    assert stuck.k_twist == pytest.approx(16 / 3 * a**3 / (1 / G1 + 1 / G2) * share**3,
                                          rel=1e-14)
    assert not stuck.sliding and stuck.slipped is None and stuck.k_across == 0
    # sliding: the slip's tangential part gives the direction; k_across = μN/|slip| below k0
    slip = np.array([2e-5, -1e-5, 5e-6]) + 3e-5 * n
    tangential = P @ slip
    sliding = ContactModel.of(slip=slip, sliding=True, **common)
    np.testing.assert_allclose(sliding.slip_direction, tangential / np.linalg.norm(tangential),
                               rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(sliding.slipped, tangential, rtol=1e-14, atol=1e-20)
    assert sliding.k_across == pytest.approx(mu * N / np.linalg.norm(tangential), rel=1e-14)
    assert mu * N / np.linalg.norm(tangential) < k0
    assert sliding.k_stick == pytest.approx(k0, rel=1e-14)
    assert sliding.k_loading == 0 and sliding.k_twist == 0
    # a tiny slip: μN/|slip| above k0, capped at k0
    tiny = ContactModel.of(slip=slip * 1e-6, sliding=True, **common)
    assert tiny.k_across == pytest.approx(k0, rel=1e-14)
    # no slip at all: along the force, stiffness k0 across
    still = ContactModel.of(slip=3e-7 * n, sliding=True, **common)
    T = common["tangential_force"]
    np.testing.assert_allclose(still.slip_direction, T / np.linalg.norm(T), rtol=1e-14)
    assert still.k_across == pytest.approx(k0, rel=1e-14)
    # ... but a tangential slip of 3e-9 of a normal one is a slip: its direction
    t = P @ np.array([0.0, 1.0, -1.0])
    t /= np.linalg.norm(t)
    small = ContactModel.of(slip=3e-7 * n + 1e-15 * t, sliding=True, **common)
    np.testing.assert_allclose(small.slip_direction, t, rtol=0, atol=1e-6)
    # sliding in pure torsion (every cell slips round the centre): no mean slip and no net
    # force, so no direction is preferred; the model slides along some unit tangent, k0 across
    spin = ContactModel.of(**{**common, "tangential_force": np.zeros(3)}, slip=3e-7 * n,
                           sliding=True)
    assert spin.sliding and spin.k_across == pytest.approx(k0, rel=1e-14)
    assert np.linalg.norm(spin.slip_direction) == pytest.approx(1.0, rel=1e-14)
    assert abs(spin.slip_direction @ n) < 1e-15
    # frictionless, or not pressed: no tangential stiffness
    for changes in ({"mu": 0.0}, {"normal_force": 0.0}):
        free = ContactModel.of(**{**common, **changes, "slip": slip, "sliding": True})
        assert free.k_stick == 0 and free.k_loading == 0 and not free.sliding
    # open (no approach): no normal stiffness
    assert ContactModel.of(**{**common, "approach": 0.0}, slip=slip,
                           sliding=False).k_normal == 0


def test_an_open_contacts_spring_carries_nothing_and_has_the_given_stiffnesses():
    n = np.array([0.0, 0.6, 0.8])
    spring = ContactModel.spring(normal=n, point=np.ones(3), centre_a=np.zeros(3),
                                 centre_b=2 * np.ones(3), stiffness=3e6, tangential=2e6, mu=0.3)
    assert spring.normal_force == 0 and not spring.tangential_force.any()
    assert spring.twist_moment == 0 and spring.k_twist == 0 and not spring.sliding
    assert (spring.k_normal, spring.k_stick, spring.k_loading, spring.mu) == (3e6, 2e6, 2e6, 0.3)
    np.testing.assert_array_equal(spring.normal, n)
    np.testing.assert_array_equal(spring.point, np.ones(3))
    np.testing.assert_array_equal(spring.centre_b, 2 * np.ones(3))
    assert not spring.curvature_a.any() and not spring.curvature_b.any()
    # by default frictionless, without a tangential stiffness
    plain = ContactModel.spring(normal=n, point=np.ones(3), centre_a=np.zeros(3),
                                centre_b=2 * np.ones(3), stiffness=3e6)
    assert (plain.k_stick, plain.k_loading, plain.mu) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("q", [0.05, 0.4, 0.9])
def test_the_stick_contacts_dT_dN_is_the_derivative_of_cattaneo_mindlin(q):
    """Cattaneo-Mindlin: T(N, s) = μN [1 − (1 − s/s*)^(3/2)] with s* = 3μN/(16 G* a) and
    a ∝ N^(1/3), so s* ∝ N^(2/3). At the shift s where T/(μN) = q, dT/dN at a fixed s by
    central differences against :meth:`ContactModel._stick_normal` (along T)."""
    mu, N = 0.3, 1.7
    c = 2e-6                                          # s* = c N^(2/3), m

    def T(normal):
        return mu * normal * (1 - (1 - s / (c * normal ** (2 / 3))) ** 1.5)

    s = c * N ** (2 / 3) * (1 - (1 - q) ** (2 / 3))
    assert T(N) == pytest.approx(q * mu * N, rel=1e-12)
    h = 1e-6 * N
    slope = (T(N + h) - T(N - h)) / (2 * h)
    direction = np.array([0.6, 0.0, -0.8])
    model = ContactModel.spring(normal=np.array([0.8, 0.0, 0.6]), point=np.zeros(3),
                                centre_a=np.zeros(3), centre_b=np.ones(3), stiffness=1.0)
    from dataclasses import replace
    model = replace(model, normal_force=N, mu=mu, tangential_force=q * mu * N * direction)
    np.testing.assert_allclose(model._stick_normal(), slope * direction, rtol=1e-6)
    # at the cone (rounded past it), fully sliding: T = μN, dT/dN = μ along T
    at_cone = replace(model, tangential_force=mu * N * (1 + 1e-12) * direction)
    np.testing.assert_allclose(at_cone._stick_normal(), mu * direction, rtol=1e-9)
    # no force, no friction or no load: nothing
    for changes in ({"tangential_force": np.zeros(3)}, {"mu": 0.0}, {"normal_force": 0.0}):
        assert not replace(model, **changes)._stick_normal().any()


def two_spheres(rng, *, T0, m0):
    """Two touching spheres (R_a = 1 mm, R_b = 0.6 mm) overlapping by δ₀ along a random normal
    n₀ with a tangential force T0 on a, a twist m0 (N m), and their model."""
    Ra, Rb, N0, kn, d0 = 1.0e-3, 0.6e-3, 0.8, 2.0e6, 2e-8
    n0 = rng.standard_normal(3)
    n0 /= np.linalg.norm(n0)
    ca0 = rng.standard_normal(3) * 1e-3
    cb0 = ca0 + (Ra + Rb - d0) * n0
    P = I3 - np.outer(n0, n0)
    T0 = P @ T0
    area = 2e-9
    model = ContactModel.of(
        normal=n0, point=ca0 + (Ra - d0 / 2) * n0, centre_a=ca0, centre_b=cb0, normal_force=N0,
        tangential_force=T0, twist_moment=m0, approach=1.5 * N0 / kn, area=area,
        stick_area=area, mu=0.6, slip=np.zeros(3), compliance=5e-9, torsion=2.6e-9,
        curvature_a=P / Ra, curvature_b=P / Rb, sliding=False)
    return model, dict(Ra=Ra, Rb=Rb, N0=N0, kn=kn, d0=d0, n0=n0, ca0=ca0, cb0=cb0, T0=T0,
                       m0=m0, k_twist=16.0 / 3.0 * (area / np.pi) ** 1.5 / 2.6e-9)


def test_the_base_blocks_carry_a_tangential_force_and_a_twist_along_as_the_spheres_move():
    """The two spheres of the test above with a tangential force T₀ (0.4 N on N₀ = 0.8 N) and a
    twist m₀: under any rigid motion the contact point stays at c_a + (R_a − δ/2) n, T₀ stays
    in the tangent plane (T = T₀ − n (n·T₀), the base blocks hold no tangential law) and the
    twist turns with the normal, so F_a = −N n + T, M_a = (x_p − c_a) × F_a + m n, and b
    carries the opposite force with M_b = −(x_p − c_b) × F_a − m n. The base blocks against
    central differences of that wrench (the moments of T about both centres are seen now)."""
    rng = np.random.default_rng(5)
    model, g = two_spheres(rng, T0=np.array([0.3, -0.2, 0.25]), m0=2e-5)
    stack = ModelStack([model])
    n0, T0 = g["n0"], g["T0"]

    def wrenches(x):
        ca, pa, cb, pb = x[:3] + g["ca0"], x[3:6], x[6:9] + g["cb0"], x[9:]
        d = cb - ca
        n = d / np.linalg.norm(d)
        overlap = g["Ra"] + g["Rb"] - np.linalg.norm(d)
        N = g["N0"] + g["kn"] * (overlap - g["d0"])
        f = -N * n + T0 - n * (n @ T0)
        m = (g["m0"] + g["k_twist"] * (n0 @ (pb - pa))) * n
        xp = ca + (g["Ra"] - g["d0"] / 2) * n
        return np.concatenate([np.concatenate([f, np.cross(xp - ca, f) + m]),
                               np.concatenate([-f, -np.cross(xp - cb, f) - m])])

    fd = _central_differences(wrenches)
    block = np.vstack([stack.base_a[0], stack.base_b[0]])
    # the model's levers run to the pressure centroid, δ₀/2 inside a's surface: an error of
    # O(δ₀/R) = 1e-5 of each quadrant's scale (N₀/R_a for a force per translation, N₀ R_a for
    # a moment per rotation, N₀ else) or of the entry (k_n's), measured; tolerance 1e-4
    scale = np.where(np.repeat([False, True, False, True], 3)[None, :],
                     np.array([[g["N0"]]] * 3 + [[g["N0"] * g["Ra"]]] * 3),
                     np.array([[g["N0"] / g["Ra"]]] * 3 + [[g["N0"]]] * 3))
    scale = np.vstack([scale, scale])
    error = np.abs(block - fd) / (scale + np.abs(fd))
    assert (error <= 1e-4).all(), error
    # T's moments and the twist's turn are seen: the same blocks with T₀ = 0 and m₀ = 0 miss
    bare, _ = two_spheres(np.random.default_rng(5), T0=np.zeros(3), m0=0.0)
    bare_block = np.vstack([ModelStack([bare]).base_a[0], ModelStack([bare]).base_b[0]])
    assert (np.abs(bare_block - fd) > 1e-2 * scale).any()
    # and the wrenches of the current force and twist
    np.testing.assert_allclose(np.concatenate([stack.wrench_a[0], stack.wrench_b[0]]),
                               wrenches(np.zeros(12)), rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("stepping", [False, True])
def test_the_shift_increments_rows_are_the_derivatives_of_the_evaluated_increment(stepping):
    """The tangential rows against central differences of the shift the evaluation computes
    for the two spheres. Without the step's kinematics: the relative displacement of b's
    material point at x_p to a's, P₀ [(c_b + R_b(φ_b)(x_p − c_b)) − (c_a + R_a(φ_a)(x_p − c_a))]
    with rotation matrices. With them (the cluster's pair shift, midpoint rule): each body
    since the start of the step moved by Δc and turned by Δφ (a composed rotation), its motion
    at the contact is Δc + Δφ × ½(r₀ + r) with r the lever of the contact point
    c_a + (R_a − δ/2) n from its centre now and r₀ at the start, and the increment is
    f P₀ (motion_b − motion_a) for the share f of the motion the contact sees."""
    rng = np.random.default_rng(17)
    model, g = two_spheres(rng, T0=np.array([0.3, -0.2, 0.25]), m0=0.0)
    n0 = g["n0"]
    P0 = I3 - np.outer(n0, n0)
    xp0 = model.point
    start_a, start_b = rng.standard_normal(3) * 1e-4, rng.standard_normal(3) * 1e-4
    turn_a, turn_b = rng.standard_normal(3) * 3e-4, rng.standard_normal(3) * 3e-4
    lever0_a = xp0 - g["ca0"] + rng.standard_normal(3) * 1e-5
    lever0_b = xp0 - g["cb0"] + rng.standard_normal(3) * 1e-5
    fraction = 0.7
    if stepping:
        model = model.stepping(mid_a=0.5 * (lever0_a + xp0 - g["ca0"]),
                               mid_b=0.5 * (lever0_b + xp0 - g["cb0"]), turn_a=turn_a,
                               turn_b=turn_b, fraction=fraction)
    stack = ModelStack([model])

    def shift(x):
        ua, pa, ub, pb = x[:3], x[3:6], x[6:9], x[9:]
        ca, cb = g["ca0"] + ua, g["cb0"] + ub
        if not stepping:
            moved_b = cb + Rotation.from_rotvec(pb).apply(xp0 - g["cb0"])
            moved_a = ca + Rotation.from_rotvec(pa).apply(xp0 - g["ca0"])
            return P0 @ (moved_b - moved_a)
        d = cb - ca
        n = d / np.linalg.norm(d)
        xp = ca + (g["Ra"] - g["d0"] / 2) * n
        motion = []
        for c, phi, turn, lever0, start in ((ca, pa, turn_a, lever0_a, start_a),
                                            (cb, pb, turn_b, lever0_b, start_b)):
            dphi = (Rotation.from_rotvec(phi) * Rotation.from_rotvec(turn)).as_rotvec()
            motion.append(c - start + np.cross(dphi, 0.5 * (lever0 + xp - c)))
        return fraction * P0 @ (motion[1] - motion[0])

    fd = _central_differences(shift)
    rows = stack.tangential_rows[0]
    # columns: translations (m/m), rotations (m/rad, scale the lever 1 mm); the composition of
    # the rotations differs from their sum (the model's) by O(|Δφ|) = 3e-4 relative (measured
    # 2.1e-4; the translation columns 3e-10)
    rotation = np.repeat([False, True, False, True], 3)[None, :]
    error = np.abs(rows - fd) / np.where(rotation, 1e-3, 1.0)
    assert (error <= np.where(rotation, 1e-3, 1e-8)).all(), error
    assert np.abs(fd[:, rotation[0]]).max() > 1e-4 and np.abs(fd).max() > 0.1


@pytest.mark.parametrize("both_ways", [True, False])
def test_the_stacked_laws_at_the_edges_are_the_per_contact_laws(monkeypatch, both_ways):
    """The cases the random contacts miss, against the per-contact law: a contact that carries
    nothing (k₀ = 0 with μ > 0: frictionless, the slide branch), an open contact's spring with
    a tangential stiffness but μ = 0, or a stiffness of 0.5 N/m (unit-free: a threshold at
    1 N/m would pass the springs of real contacts), every contact with no predicted motion
    (ds = 0: a sliding contact goes on along its slip, a stick one stays on its stick
    branch)."""
    monkeypatch.setattr(stiffness, "_TANGENT_BOTH_WAYS", both_ways)
    rng = np.random.default_rng(23)
    models = [m for m in random_contacts(rng, 12) if m.mu > 0]
    n = np.array([0.0, 0.6, 0.8])
    models += [
        ContactModel.of(normal=n, point=np.zeros(3), centre_a=-n, centre_b=n, normal_force=0.0,
                        tangential_force=np.zeros(3), twist_moment=0.0, approach=0.0,
                        area=1e-8, stick_area=1e-8, mu=0.4, slip=np.zeros(3),
                        compliance=5e-9, torsion=2.6e-9, curvature_a=np.zeros((3, 3)),
                        curvature_b=np.zeros((3, 3)), sliding=False),
        ContactModel.spring(normal=n, point=np.zeros(3), centre_a=-n, centre_b=n,
                            stiffness=1e6, tangential=2e5, mu=0.0),
        ContactModel.spring(normal=n, point=np.zeros(3), centre_a=-n, centre_b=n,
                            stiffness=1e6, tangential=0.5, mu=0.3)]
    assert models[-3].k_stick == 0 and models[-3].mu > 0
    stack = ModelStack(models)
    count = len(models)
    for ds, dN in ((np.zeros((count, 3)), np.zeros(count)),
                   (np.array([(I3 - np.outer(m.normal, m.normal)) @ rng.standard_normal(3)
                              for m in models]) * 1e-8, -0.5 * stack.normal_force)):
        laws = stack.laws(ds, dN)
        for k, m in enumerate(models):
            S, g, offset, slide = reference_law(m, ds[k], dN[k])
            np.testing.assert_allclose(laws.stiffness[k], S, rtol=1e-12, atol=1e-30)
            np.testing.assert_allclose(laws.g[k], g, rtol=1e-12, atol=1e-30)
            np.testing.assert_allclose(laws.offset[k], offset, rtol=1e-12, atol=1e-30)
            assert laws.slide[k] == slide, k
    assert any(m.sliding for m in models) and any(not m.sliding for m in models[:-3])
    np.testing.assert_array_equal(stack.normal, [m.normal for m in models])
    # the elastic predictor's arrays have the laws' shapes and types
    elastic = stack.elastic()
    assert elastic.g.shape == (count, 3) and elastic.offset.shape == (count, 3)
    assert elastic.slide.dtype == bool and elastic.slide.shape == (count,)


def test_the_approach_row_is_taken_at_the_first_touch():
    """Two spheres: their overlap R_a + R_b − |c_b − c_a| does not change when either turns
    about its centre. The pressure centroid may lie off the line of centres (here 20 µm: a
    contact's tractions are not symmetric), the closest points of the undeformed surfaces
    (``touch``) do not: the approach row's rotation columns are zero, its translation columns
    ∓n (central differences of the overlap)."""
    from dataclasses import replace

    rng = np.random.default_rng(29)
    model, g = two_spheres(rng, T0=np.array([0.3, -0.2, 0.25]), m0=0.0)
    n0 = g["n0"]
    side = np.cross(n0, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    model = replace(model, point=model.point + 2e-5 * side, touch=model.point)
    row = ModelStack([model]).approach_rows[0]
    np.testing.assert_allclose(row, np.concatenate([n0, np.zeros(3), -n0, np.zeros(3)]),
                               rtol=0, atol=1e-12)
    # at the pressure centroid instead the rotations would move it by n·(dφ × 20 µm side)
    assert np.linalg.norm(np.cross(side, n0)) * 2e-5 > 1e-6


def test_the_single_pair_cross_product_and_skew_are_numpys():
    """:func:`stiffness.cross` (the cluster's pair kinematics) and :func:`skew` against
    numpy's cross product, on vectors with every component non-zero."""
    rng = np.random.default_rng(31)
    for _ in range(5):
        u, v = rng.standard_normal(3), rng.standard_normal(3)
        np.testing.assert_allclose(stiffness.cross(u, v), np.cross(u, v), rtol=1e-14,
                                   atol=1e-15)
        np.testing.assert_allclose(skew(u) @ v, np.cross(u, v), rtol=1e-14, atol=1e-15)


def test_laws_where_takes_the_other_laws_row_by_row():
    """:meth:`TangentialLaws.where` (the cluster's active set mixes branches so): every array
    from ``other`` on the masked contacts and from ``self`` on the rest."""
    rng = np.random.default_rng(37)

    def laws(slide):
        return stiffness.TangentialLaws(rng.standard_normal((4, 3, 3)),
                                        rng.standard_normal((4, 3)),
                                        rng.standard_normal((4, 3)), np.full(4, slide))

    mine, other = laws(False), laws(True)
    mask = np.array([True, False, False, True])
    mixed = mine.where(mask, other)
    for k in range(4):
        source = other if mask[k] else mine
        np.testing.assert_array_equal(mixed.stiffness[k], source.stiffness[k])
        np.testing.assert_array_equal(mixed.g[k], source.g[k])
        np.testing.assert_array_equal(mixed.offset[k], source.offset[k])
        assert mixed.slide[k] == source.slide[k]


def test_an_empty_stack_has_the_shapes_of_no_contacts():
    """A cluster pass with no contact at all still stacks its (zero) contacts: every array
    keeps its trailing shape, so the Newton step's sums over contacts are empty, not
    misshaped."""
    stack = ModelStack([])
    assert stack.tangential_force.shape == (0, 3) and stack.normal_force.shape == (0,)
    assert stack.arm_a.shape == (0, 3) and stack.approach_rows.shape == (0, 12)
    assert stack.base_a.shape == (0, 6, 12) and stack.wrench_b.shape == (0, 6)
    assert stack.laws(np.zeros((0, 3)), np.zeros(0)).stiffness.shape == (0, 3, 3)
