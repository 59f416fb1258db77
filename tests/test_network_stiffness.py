"""The contact models' tangential laws evaluated for many contacts at once
(:class:`thirdbody.network.stiffness.ModelStack`) against the law written out for one contact
at a time (the form the Newton step used before it was vectorised, kept here as the reference)
on random contacts in every state: stick cells inside and beyond the cone, sliding on along
the slip, reversed back to stick and beyond, frictionless."""

import numpy as np
import pytest

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
        return (model.k_across * (P - np.outer(d, d)), model.mu * d,
                model.mu * model.normal_force * d - T, True)
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

    steps = np.array([1e-9] * 3 + [1e-6] * 3 + [1e-9] * 3 + [1e-6] * 3)
    fd_a, fd_b, fd_delta = np.zeros((6, 12)), np.zeros((6, 12)), np.zeros(12)
    for j in range(12):
        e = np.zeros(12)
        e[j] = steps[j]
        plus, minus = wrenches(e), wrenches(-e)
        fd_a[:, j] = (plus[0] - minus[0]) / (2 * steps[j])
        fd_b[:, j] = (plus[1] - minus[1]) / (2 * steps[j])
        fd_delta[j] = (plus[2] - minus[2]) / (2 * steps[j])
    # absolute tolerances by quadrant: force or moment rows, translation or rotation columns
    rotation = np.repeat([False, True, False, True], 3)
    atol = 1e-6 * np.where(rotation[None, :], np.array([[N0]] * 3 + [[N0 * Ra]] * 3),
                           np.array([[kn]] * 3 + [[N0]] * 3))
    for block, fd in ((stack.base_a[0], fd_a), (stack.base_b[0], fd_b)):
        assert (np.abs(block - fd) <= atol + 1e-5 * np.abs(fd)).all(), block - fd
    assert np.abs(fd_a[3:, 9:]).max() > 1e3 * atol[3:, 9:].max()        # the twist is seen
    np.testing.assert_allclose(stack.approach_rows[0], fd_delta, rtol=1e-6, atol=1e-9)
