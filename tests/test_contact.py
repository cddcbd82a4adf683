"""The contact stage: forces and memory against their NumPy twin, pairs against brute force.

- ``reference_contact.contact_force`` (overlap from ``polygon.overlap``, itself held against
  shapely) against the kernel on seeded random overlapping pairs, new and remembered.
- The spatial hash finds exactly the overlapping pairs of an all-pairs search, never across
  worlds of a batch.
- Rate-and-state memory: theta persists through a contact and restarts in equilibrium
  for a new one; more contacts than slots is an error, never silent.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from taichi_ice import CapacityError, Simulation, backend
from taichi_ice.codes import BodyEnergy, OverlapKind, Status
from taichi_ice.engine.reference import ReferenceModel, ReferenceState, outline, owns
from taichi_ice.engine.reference_contact import ContactMemory, contact_force
from taichi_ice.engine.schema import FORCE_QUANTUM
from taichi_ice.engine.world import World
from taichi_ice.physics.friction import Coulomb, RateState
from taichi_ice.physics.polygon import check_polygon, overlap, sat_separated, transform
from taichi_ice.physics.slip import NO_INTERFACE
from taichi_ice.run.runfile_read import read_run
from taichi_ice.scene.parse import reseeded, scene_from_dict

SEED = 20240612
N_PAIRS = 160  # one two-body world each; four in five overlap

# Same formulas in the same order; what differs is LLVM's and NumPy's rounding of the clip
# (geometry's Taichi-vs-NumPy tolerance is 1e-12 relative), carried into forces ~1e4 N.
TWIN_RTOL = 1e-10
# Each force component is truncated to 2^-24 N once per pair in the kernel and in the twin;
# round-off can move it across one step of that fixed point.
FORCE_ATOL = 2 * FORCE_QUANTUM  # N (and N m for torques)
# theta against its exponential update from the slip the test computes: round-off of the
# slip rate (float32: its 1e-7) through ln(V / V*).
THETA_RTOL = {"f64": 1e-9, "f32": 1e-5}
# On a device whose compiler fuses a * b + c into one rounding (CUDA's NVPTX, SPIR-V
# drivers: test_fmath, test_geometry) the kernel's round-off is not the twin's, and where the
# overlap's clip cancels (nearly parallel edges crossing) the slip rate carries round-off
# above TWIN_RTOL: the twin's own V moves by up to 2.4e-10 relative when its outlines move by
# an ulp, which re-rolls its roundings (measured on this test's pairs on the CPU: 19 of 103
# sliding contacts by more than 1e-12), and an H100 gave 1.8e-10 against the twin. There the
# slip rate and theta are held to the twin within ROUNDOFF_SPREAD times the twin's own spread
# under such noise, measured per contact (ROUNDOFF_DRAWS draws).
ROUNDOFF_SPREAD = 4.0
ROUNDOFF_DRAWS = 16

KIND_PAIRS = (
    ("dynamic", "dynamic"),
    ("dynamic", "fixed"),
    ("fixed", "dynamic"),
    ("kinematic", "dynamic"),
    ("dynamic", "kinematic"),
)


@pytest.fixture(scope="module")
def f64(taichi_runtime: tuple[str, str]) -> None:
    """Skip tolerances that only float64 meets."""
    if taichi_runtime[1] != "f64":
        pytest.skip("needs float64 (tolerances near round-off)")


@pytest.fixture(scope="module")
def run_opts(taichi_runtime: tuple[str, str]) -> dict:
    arch, precision = taichi_runtime
    return {"arch": arch, "precision": precision}


def random_quad(rng: np.random.Generator) -> np.ndarray:
    """A strictly convex counter-clockwise quadrilateral on a random ellipse (m)."""
    while True:
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, 4))
        gaps = np.diff(np.append(angles, angles[0] + 2.0 * np.pi))
        if gaps.min() > 0.4:
            break
    semi = rng.uniform(0.25, 0.7, 2)
    return check_polygon(np.stack([semi[0] * np.cos(angles), semi[1] * np.sin(angles)], 1))


def pair_scenes(rng: np.random.Generator, law, ice=None) -> tuple[list, np.ndarray, np.ndarray]:
    """Two-body scenes (laid apart, as scene files must be) and the overlapping placements.

    Returns:
        (scenes, positions (2B, 2), angles (2B,)): the second body of each pair is slid
        toward the first until the outlines touch, then pushed in by up to 5 cm (or, for one
        pair in five, held 1-5 mm apart).
    """
    scenes, pos, ang = [], [], []
    for b in range(N_PAIRS):
        kinds = KIND_PAIRS[b % len(KIND_PAIRS)]
        bodies = []
        for k, kind in enumerate(kinds):
            body = {
                "name": f"p{k}",
                "kind": kind,
                "shape": "polygon",
                "vertices": random_quad(rng).tolist(),
                "position": [30.0 * k, 0.0],
            }
            if kind != "fixed":
                body["velocity"] = rng.uniform(-1.0, 1.0, 2).tolist()
                body["omega"] = float(rng.uniform(-2.0, 2.0))
            bodies.append(body)
        # At 0.2 of the limit for every law (rate and state's "auto" is 0.05), where a
        # sliding contact's step is taken in sub-steps on most pairs.
        sim = {"duration": 1.0, "dt_safety": 0.2}
        raw = {"simulation": sim, "friction": law.to_dict(), "body": bodies}
        scene = scene_from_dict({**raw, "ice": ice} if ice else raw)
        a = rng.uniform(0.0, 2.0 * np.pi, 2)
        p = transform(scene.bodies[0].vertices, [0.0, 0.0], a[0])
        q0 = transform(scene.bodies[1].vertices, [0.0, 0.0], a[1])
        direction = np.array([math.cos(t := rng.uniform(0, 2 * np.pi)), math.sin(t)])
        lo, hi = 0.0, 3.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if sat_separated(p, q0 + mid * direction) else (mid, hi)
        # Overlap depths over five decades: both the normal force and the tangential spring
        # scale with the contact width, so shallow contacts slip and deep ones stick.
        if b % 5 == 4:
            push = -rng.uniform(1e-3, 5e-3)  # apart
        elif b % 5 == 3:
            push = rng.uniform(0.05, 0.9) * hi  # deep: containment and other fallbacks
        else:
            push = 10.0 ** rng.uniform(-6.0, -1.3)
        centre = rng.uniform(-3.0, 3.0, 2)  # pairs of different worlds overlap in space
        pos += [centre, centre + (hi - push) * direction]
        ang += [a[0], a[1]]
        scenes.append(scene)
    return scenes, np.array(pos), np.array(ang)


def kernel_contacts(world: World) -> dict:
    """``{(owner, partner): (xi, elastic, theta, slip)}`` from the contact slots."""
    d = world.data
    count = d.contact_count.to_numpy()
    partner = d.contact_partner.to_numpy()
    xi, elastic = d.contact_xi.to_numpy(), d.contact_elastic.to_numpy()
    theta = d.contact_theta.to_numpy() if world.layout.rate_state else None
    slip = d.contact_slip.to_numpy() if world.layout.rate_state else None
    out = {}
    for i in range(world.batch.n_bodies):
        for s in range(count[i]):
            th = float(theta[i, s]) if theta is not None else 0.0
            out[(i, int(partner[i, s]))] = (
                float(xi[i, s]),
                float(elastic[i, s]),
                th,
                float(slip[i, s]) if slip is not None else 0.0,
            )
    return out


def roundoff_spread(pair, p, q, memory, rng) -> tuple[float, float]:
    """ROUNDOFF_SPREAD times the largest change of the twin's slip rate and theta when every
    coordinate of the outlines ``p``, ``q`` moves by an ulp or stays (drawn ROUNDOFF_DRAWS
    times): the round-off the twin's own arithmetic leaves in them."""
    eps = np.finfo(np.float64).eps
    d_slip = d_theta = 0.0
    for _ in range(ROUNDOFF_DRAWS):
        moved = pair(*(x * (1.0 + eps * rng.integers(-1, 2, x.shape)) for x in (p, q)))
        if moved is not None:
            d_slip = max(d_slip, abs(moved.memory.slip - memory.slip))
            d_theta = max(d_theta, abs(moved.memory.theta - memory.theta))
    return ROUNDOFF_SPREAD * d_slip, ROUNDOFF_SPREAD * d_theta


@pytest.mark.parametrize(
    "law, ice",
    [(Coulomb(0.4), None), (RateState(), None), (RateState(), {"slide_resolution": 0.002})],
    ids=["coulomb", "rate-state", "rate-state-sub-steps"],
)
def test_contact_twin_matches_kernel_on_random_pairs(f64, law, ice):
    """Force, torque, memory and dissipation of one contact of the Euler step match the
    NumPy twin, twice: the damped stick spring, the slip rate and theta, and the work booked
    at the mid-step velocity; with ``[ice] slide_resolution``, the slide in sub-steps. (The
    analytic steps' contacts, Coulomb's default among them: test_contact_coupled.py.)"""
    rng = np.random.default_rng(SEED)
    scenes, pos, ang = pair_scenes(rng, law, ice)
    world = World(scenes, integrator="euler")
    model = ReferenceModel.from_scenes(scenes)
    d = world.data
    vel, omega = world.velocities(), world.omegas()
    state = ReferenceState(pos=pos, angle=ang, vel=vel, omega=omega)
    # Each body's last velocity change, with which the contacts book their work at the
    # mid-step velocity (``contact_law.contact_work``): random, as after a step; the
    # fields' rows past the bodies (their capacity) stay zero.
    dvel = rng.uniform(-0.05, 0.05, vel.shape)
    domega = rng.uniform(-0.05, 0.05, omega.shape)
    rest = world.layout.n_bodies - len(vel)
    d.body_dvel.from_numpy(np.pad(dvel, ((0, rest), (0, 0))))
    d.body_domega.from_numpy(np.pad(domega, (0, rest)))
    memory: dict = {}
    fused = backend.actual_arch() != "cpu"  # the CPU compiles IEEE as written
    rng_noise = np.random.default_rng(SEED + 1)
    seen = {"slip": 0, "stick": 0, "fallback": 0, "remembered": 0, "severed": 0, "sub-stepped": 0}
    worst = 0.0  # largest force difference (N)
    for step in range(2):
        world.place(state.pos, state.angle)
        d.body_force_q.fill(0)
        d.body_torque_q.fill(0)
        d.body_energy.fill(0.0)
        world.refresh_lists()
        world.contacts.compute()
        force_q = d.body_force_q.to_numpy()
        torque_q = d.body_torque_q.to_numpy()
        energy = d.body_energy.to_numpy()
        contacts = kernel_contacts(world)
        expected, spread = {}, {}
        for w in range(N_PAIRS):
            a, b = 2 * w, 2 * w + 1
            i, j = (a, b) if owns(model.kind, a, b) else (b, a)
            origin = state.pos[i]
            p, q = outline(model, state, i, origin), outline(model, state, j, origin)
            pair = functools.partial(
                contact_force,
                pos_owner=np.zeros(2),
                vel_owner=state.vel[i],
                omega_owner=state.omega[i],
                pos_partner=state.pos[j] - origin,
                vel_partner=state.vel[j],
                omega_partner=state.omega[j],
                dt=world.dt,
                k_e=float(model.k_e[w]),
                k_v=float(model.k_v[w]),
                ratio=float(model.ratio[w]),
                law=model.laws[w],
                inv_mass=(model.inv_mass(i), model.inv_mass(j)),
                inv_inertia=(model.inv_inertia(i), model.inv_inertia(j)),
                zeta=float(model.zeta[w]),
                slide_resolution=float(model.slide_resolution[w]),
                dvel=(dvel[i], dvel[j]),
                domega=(float(domega[i]), float(domega[j])),
                memory=memory.get((i, j)),
            )
            c = pair(p, q)
            # A contact that ended books what it held (``SEVERED``).
            held = memory[(i, j)].elastic if (i, j) in memory and c is None else 0.0
            assert energy[i, BodyEnergy.SEVERED] == pytest.approx(held, rel=1e-8, abs=1e-15)
            if c is None:
                seen["severed"] += (i, j) in memory
                for k in (i, j):
                    assert np.all(force_q[k] == 0) and torque_q[k] == 0
                continue
            expected[(i, j)] = c.memory
            if ice and pair(p, q, slide_resolution=0.0).memory.xi != c.memory.xi:
                seen["sub-stepped"] += 1  # the sub-steps changed the slide: they were taken
            if fused:
                spread[(i, j)] = roundoff_spread(pair, p, q, c.memory, rng_noise)
            seen["slip" if abs(c.tangential_force) >= c.mu * c.normal_force else "stick"] += 1
            seen["fallback"] += c.kind == OverlapKind.FALLBACK
            seen["remembered"] += (i, j) in memory
            scale = np.linalg.norm(c.force)
            for k, f, tau, r in (
                (j, c.force, c.torque_partner, c.point - (state.pos[j] - origin)),
                (i, -c.force, c.torque_owner, c.point),
            ):
                got = force_q[k] * FORCE_QUANTUM
                worst = max(worst, float(np.max(np.abs(got - f))))
                tol = TWIN_RTOL * scale + FORCE_ATOL
                assert np.all(np.abs(got - f) <= tol), (step, w, got, f)
                tol_tau = TWIN_RTOL * scale * np.linalg.norm(r) + FORCE_ATOL
                assert abs(torque_q[k] * FORCE_QUANTUM - tau) <= tol_tau, (step, w)
            assert energy[i, BodyEnergy.FRICTION] == pytest.approx(c.slip_work, rel=1e-8, abs=1e-12)
            assert energy[i, BodyEnergy.VISCOUS] == pytest.approx(
                c.viscous_work, rel=1e-8, abs=1e-12
            )
        assert set(contacts) == set(expected)
        for key, (xi, elastic, theta, slip) in contacts.items():
            want = expected[key]
            d_slip, d_theta = spread.get(key, (0.0, 0.0))
            assert slip == pytest.approx(want.slip, rel=TWIN_RTOL, abs=max(1e-15, d_slip))
            assert xi == pytest.approx(want.xi, rel=1e-8, abs=1e-15)
            assert elastic == pytest.approx(want.elastic, rel=1e-8, abs=1e-12)
            assert theta == pytest.approx(want.theta, rel=TWIN_RTOL, abs=max(1e-15, d_theta))
        memory = expected
        # Half a millisecond later, without the forces: the same pairs, most still touching.
        state.pos = state.pos + 5e-4 * state.vel
        state.angle = state.angle + 5e-4 * state.omega
    print(f"{seen}; largest force difference {worst / FORCE_QUANTUM:.0f} x 2^-24 N")
    assert seen["slip"] > 20 and seen["stick"] > 20 and seen["remembered"] > 50
    assert seen["severed"] > 5  # contacts that ended on the second step
    assert seen["fallback"] > 0
    assert (seen["sub-stepped"] > 10) == bool(ice)


# --------------------------------------------------------------------------------------------
# Broad phase
# --------------------------------------------------------------------------------------------


def dense_field_scene(seed: int) -> dict:
    """A 12 x 20 field of blocks and two long walls (moved into place after set-up)."""
    return {
        "simulation": {"duration": 1.0, "seed": seed},
        "body": [
            {
                "name": "wall_a",
                "kind": "fixed",
                "shape": "rectangle",
                "width": 12.0,
                "length": 0.4,
                "position": [5.0, -5.0],
            },
            {
                "name": "wall_b",
                "kind": "fixed",
                "shape": "rectangle",
                "width": 0.4,
                "length": 12.0,
                "position": [-5.0, 5.0],
            },
        ],
        "field": [
            {
                "shape": "diamond",
                "width": 0.5,
                "length": 0.6,
                "rows": 12,
                "columns": 10,
                "origin": [0.0, 0.0],
                "spacing": [0.8, 0.8],
                "jitter": 0.05,
            },
            {
                "shape": "rectangle",
                "width": 0.4,
                "length": 0.3,
                "rows": 12,
                "columns": 10,
                "origin": [0.0, 10.0],
                "spacing": [0.8, 0.8],
                "jitter": 0.05,
            },
        ],
    }


def all_overlapping_pairs(outlines: list[np.ndarray], dynamic: np.ndarray) -> set:
    """Every unordered pair (at least one dynamic) whose outlines overlap with positive area.

    All pairs are tested; a bounding-circle test (a circle holds its polygon, so it can only
    drop pairs that cannot overlap) picks those worth clipping.
    """
    centre = np.array([o.mean(axis=0) for o in outlines])
    radius = np.array([np.max(np.hypot(*(o - c).T)) for o, c in zip(outlines, centre)])
    i, j = np.triu_indices(len(outlines), k=1)
    near = np.hypot(*(centre[i] - centre[j]).T) < radius[i] + radius[j]
    near &= dynamic[i] | dynamic[j]
    return {
        frozenset((int(a), int(b)))
        for a, b in zip(i[near], j[near])
        if overlap(outlines[a], outlines[b]).area > 0.0
    }


def test_spatial_hash_finds_exactly_the_overlapping_pairs(f64):
    """The hash pairs exactly the bodies an all-pairs search finds, never across worlds."""
    base = scene_from_dict(dense_field_scene(0))
    scenes = [base, reseeded(base, 1)]
    world = World(scenes)
    rng = np.random.default_rng(SEED)
    model = ReferenceModel.from_scenes(scenes)
    n = model.n_bodies
    pos = world.positions()
    ang = world.angles()
    dynamic = model.kind == 0
    # Both worlds scattered over the same 7 m square: ~3 overlaps per block, and bodies of
    # the two worlds overlap each other everywhere.
    side = 7.0
    pos[dynamic] = rng.uniform(0.0, side, (int(dynamic.sum()), 2))
    ang[dynamic] = rng.uniform(0.0, 2.0 * np.pi, int(dynamic.sum()))
    for w, sl in enumerate(world.world_slices()):
        pos[sl.start] = [side / 2, 2.0 + 3.0 * w]  # wall_a across the square
        pos[sl.start + 1] = [5.0 - 3.0 * w, side / 2]  # wall_b across the square
    world.place(pos, ang)
    world.refresh_lists()
    world.contacts.compute()
    assert world.data.status.to_numpy()[:, Status.SLOT_OVERFLOW].max() <= world.layout.slots
    state = ReferenceState(pos=pos, angle=ang, vel=world.velocities(), omega=world.omegas())
    outlines = [outline(model, state, i) for i in range(n)]
    found = {frozenset(k) for k in kernel_contacts(world)}
    for a, b in found:
        assert model.world[a] == model.world[b]
    total = 0
    for sl in world.world_slices():
        ids = np.arange(sl.start, sl.stop)
        brute = {
            frozenset(int(ids[k]) for k in pair)
            for pair in all_overlapping_pairs([outlines[k] for k in ids], dynamic[ids])
        }
        mine = {p for p in found if min(p) >= sl.start and max(p) < sl.stop}
        assert mine == brute
        total += len(brute)
    # Across worlds the bodies overlap as much as within: the hash kept them apart.
    across = all_overlapping_pairs(outlines, dynamic) - found
    print(f"{total} pairs in the two worlds; {len(across)} overlapping pairs across worlds")
    assert total > 500 and len(across) > 500


# --------------------------------------------------------------------------------------------
# Contact memory and capacity
# --------------------------------------------------------------------------------------------


def bouncing_block(law: RateState) -> dict:
    """A spinning, tilted block thrown at a floor and pressed back onto it: it bounces (at 0.2
    of the stable limit, the step it was written at; rate and state's "auto" is 0.05)."""
    tilt, half = 0.2, 0.4
    lowest = half * (math.cos(tilt) + math.sin(tilt))  # centre height of the lowest corner
    return {
        "simulation": {"duration": 1.0, "dt_safety": 0.2},
        "friction": law.to_dict(),
        "body": [
            {
                "name": "floor",
                "kind": "fixed",
                "shape": "rectangle",
                "width": 6.0,
                "length": 0.5,
                "position": [0.0, -0.25],
            },
            {
                "name": "block",
                "shape": "rectangle",
                "width": 0.8,
                "length": 0.8,
                "position": [-1.0, lowest + 2e-3],
                "angle": tilt,
                "velocity": [1.0, -0.6],
                "omega": 2.0,
                "force": [0.0, -3000.0],
            },
        ],
    }


def test_theta_persists_through_a_contact_and_restarts_for_a_new_one(
    run_opts, taichi_runtime, request
):
    """While a contact slides, theta follows the exponential update at the step's slip rate;
    a contact that slides from its first touch is a new interface at -B x, one that starts
    from rest is born at v_star (theta = 0); stuck, it has none. These are the closed forms
    of one step of the law, so the slide takes one step here (``[ice] slide_resolution =
    0``); in sub-steps (the default) each sub-step takes them at its own slip rate, held
    against the relaxation's closed form and against itself in halves in
    ``test_slide_steps.py``."""
    if taichi_runtime[1] == "f32":
        # A strict expected failure, a finding of the float32 lane (issue 28): in float32
        # the kernel's theta leaves the update at the twin's slip rate by up to 0.6 %
        # (measured on the CPU: -0.8921 against -0.8866). The likely cause, measured on
        # the carried steps: the solve finds V from f_trial - f_n mu, which in float32 loses
        # ~eps |slip| / V of V; near stick |slip| / V reaches 2e4 and theta's error 2.5e-5,
        # growing with it (correlation 0.63 of their logs). The float32 slip rate near
        # stick is not yet bounded. Run in float64 by make test.
        request.applymarker(pytest.mark.xfail(strict=True, reason="float32 slip rate"))
    law = RateState(t_c=0.01)  # short memory, so that theta moves within one contact
    scene = scene_from_dict({**bouncing_block(law), "ice": {"slide_resolution": 0.0}})
    sim = Simulation(scene, **run_opts)
    world = sim.world
    model = ReferenceModel.from_scenes([scene])
    decay = math.exp(-world.dt / law.t_c)
    rtol = THETA_RTOL[taichi_runtime[1]]
    # No interface, as the fields hold it (float32 in a float32 run).
    none = float(backend.real_dtype(taichi_runtime[1])(NO_INTERFACE))

    counts = {"new": 0, "from rest": 0, "carried": 0, "stuck": 0, "lagging": 0}
    for _ in range(round(0.25 / world.dt)):
        state = ReferenceState(
            pos=world.positions(),
            angle=world.angles(),
            vel=world.velocities(),
            omega=world.omegas(),
        )
        before = kernel_contacts(world).get((1, 0))
        memory = None
        if before is not None:
            memory = ContactMemory(xi=before[0], elastic=before[1], theta=before[2], slip=before[3])
        world.step()
        after = kernel_contacts(world).get((1, 0))
        if after is None:
            continue
        theta = after[2]
        # The sliding rate of this step, from the NumPy twin with the kernel's memory.
        c = contact_force(
            outline(model, state, 1, state.pos[1]),
            outline(model, state, 0, state.pos[1]),
            np.zeros(2),
            state.vel[1],
            state.omega[1],
            state.pos[0] - state.pos[1],
            state.vel[0],
            state.omega[0],
            dt=world.dt,
            k_e=float(model.k_e[0]),
            k_v=float(model.k_v[0]),
            ratio=float(model.ratio[0]),
            law=law,
            inv_mass=(model.inv_mass(1), model.inv_mass(0)),
            inv_inertia=(model.inv_inertia(1), model.inv_inertia(0)),
            zeta=float(model.zeta[0]),
            memory=memory,
        )
        v = abs(c.sliding_rate)
        if v < law.v_star:
            counts["stuck"] += 1
            assert theta == none  # the paper's rule: the interface ends
            continue
        steady = -law.B * math.log(v / law.v_star)
        if memory is None:
            counts["new"] += 1  # sliding from its first touch: in equilibrium at its rate
            assert theta == pytest.approx(steady, rel=rtol, abs=1e-12)
        elif memory.theta == none or memory.slip * c.sliding_rate < 0.0:
            counts["from rest"] += 1  # born at v_star (theta = 0), carried over the step
            assert theta == pytest.approx(steady * (1.0 - decay), rel=rtol, abs=1e-12)
        else:
            counts["carried"] += 1
            expected = steady + (memory.theta - steady) * decay
            assert theta == pytest.approx(expected, rel=rtol, abs=1e-12)
            counts["lagging"] += abs(theta - steady) > 0.05 * law.B
    sim.check()
    print(counts)
    assert counts["new"] + counts["from rest"] >= 2  # interfaces began more than once
    assert counts["carried"] > 20 and counts["lagging"] > 5  # memory mattered
    assert counts["stuck"] > 0


def test_more_contacts_than_slots_is_a_capacity_error(tmp_path, run_opts):
    """A body owning two contacts with one slot stops the run with CapacityError."""
    block = {"shape": "rectangle", "width": 1.0, "length": 1.0}
    scene = scene_from_dict(
        {
            "simulation": {"duration": 0.1},
            "body": [  # body 0 owns both its contacts (the lower id of two dynamic bodies)
                {**block, "name": "middle", "position": [0.0, 0.0]},
                {**block, "name": "left", "position": [-1.001, 0.0], "velocity": [1.0, 0.0]},
                {**block, "name": "right", "position": [1.001, 0.0], "velocity": [-1.0, 0.0]},
            ],
        }
    )
    path = tmp_path / "overflow.h5"
    sim = Simulation(scene, slots=1, **run_opts)
    with pytest.raises(CapacityError, match="slots"):
        sim.run(out=path)
    run = read_run(path)
    assert run["attrs"]["status"] == "failed"
    assert "slots" in run["attrs"]["failure"]
    # With the default slots the same scene runs through the collision.
    Simulation(scene, **run_opts).run(until=0.005)
