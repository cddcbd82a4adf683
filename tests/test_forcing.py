"""Ocean current, wind and Coriolis (``physics.forcing``, ``engine.forcing``), against closed
forms, conservation and a root finder that shares no code with the engine.

- A floe in a current follows the closed form of the quadratic drag ODE, ``v(t) = u + (v0 -
  u) / (1 + c |v0 - u| t / m)``, at first order in dt; in a geostrophic current with
  Coriolis the tilt and Coriolis only turn the relative velocity, at -f.
- Free drift under wind reaches the speed where the two drags balance, along the wind; with
  Coriolis it turns to the right of the wind (northern hemisphere) by the angle that
  ``scipy.optimize.fsolve`` finds for the steady balance.
- The energy budget closes with current, wind and tilt to round-off for a lone floe
  (Coriolis does no work) and within the project's bound with contacts.
- A gridded field equal to a uniform one runs bit for bit as it; a bilinear field is
  sampled exactly at the centroid, constant beyond the grid.
- A scene without forcing runs as before; the twins agree; bad input is refused by name.

The drag coefficients are written out here from the documented law (docs/scenarios.md),
not taken from the package.
"""

# No "from __future__ import annotations": this file defines Taichi kernels.

import copy
import math

import numpy as np
import pytest
import taichi as ti

from taichi_ice.engine.reference import (
    ReferenceModel,
    ReferenceState,
    reference_energies,
    reference_step,
)
from taichi_ice.engine.world import World
from taichi_ice.errors import ScenarioError
from taichi_ice.physics import forcing, forcing_ti
from taichi_ice.run import budget
from taichi_ice.scene.parse import load_scenario, scene_from_dict

RHO_ICE, RHO_WATER = 920.0, 1010.0
FORM, SKIN = 1.0, 0.005  # the [water] defaults
RHO_AIR, C_AIR = 1.225, 1.2e-3  # the [wind] defaults

# Explicit Euler on m v' = -c |v - u| (v - u): the error of the relative velocity stays below
# this fraction of dt / T times |v0 - u| (T = m / (c |v0 - u|)); measured 0.157 from rest in
# a current (0.139 of a percent of |u| at dt / T = 8.9e-3), 0.132 in the geostrophic one.
# First order: halving dt divides it by 2 within HALVING_BAND (measured 0.498, and 0.4997
# for the position's error).
EULER_BOUND = 0.3
HALVING_BAND = (0.45, 0.55)
# A steady drift, reached after tens of its relaxation times (the slowest is m / (c |v|)):
# equal to the root finder's to this relative accuracy (measured: 12 digits of the speed).
STEADY_RTOL = 1e-8
# A lone floe's budget: the work of current, wind and tilt is its kinetic energy plus the
# drag's dissipation to round-off (measured 7e-13; an explicit Coriolis step would create
# (f dt)^2 / 2 of the kinetic energy each step: 8e-4 of it over the run below).
LONE_BUDGET_RTOL = 1e-10
# With contacts, the bound of tests/test_budget.py (the explicit step's residual; measured
# 1.1e-3 in the drifting scene's first 8 s).
CONTACT_BUDGET_RTOL = 0.01
# The NumPy twin of the step against the kernels (tests/test_engine.py's bound).
TWIN_RTOL = 1e-11


@pytest.fixture(scope="module")
def f64(taichi_runtime):
    if taichi_runtime[1] != "f64":
        pytest.skip("tolerances near float64 round-off")


# --------------------------------------------------------------------------------------------
# Scenes and closed forms
# --------------------------------------------------------------------------------------------


def floe(side: float, position=(0.0, 0.0), velocity=(0.0, 0.0), name: str = "floe") -> dict:
    return {
        "name": name,
        "shape": "rectangle",
        "width": side,
        "length": side,
        "position": list(position),
        "velocity": list(velocity),
    }


def scene(bodies, thickness: float, source: str = "forcing.toml", **tables):
    """A scene of ``bodies`` with the tables ``water``, ``wind``, ``coriolis`` given."""
    data = {"simulation": {"duration": 1e6}, "ice": {"thickness": thickness}, "body": bodies}
    data.update(copy.deepcopy(tables))
    return scene_from_dict(data, source=source)


def coefficients(side: float, thickness: float) -> tuple[float, float, float]:
    """(m kg, c water kg/m, c air kg/m) of a square floe, from the documented laws."""
    area = side * side
    draft = RHO_ICE * thickness / RHO_WATER
    diameter = 2.0 * math.sqrt(area / math.pi)
    c_water = 0.5 * RHO_WATER * (FORM * draft * diameter + SKIN * area)
    return RHO_ICE * thickness * area, c_water, RHO_AIR * C_AIR * area


def steady_drift(m, c_w, c_a, f, wind, current=(0.0, 0.0), tilt=False):
    """The steady velocity of a lone floe (scipy's root of the force balance)."""
    from scipy.optimize import fsolve

    wind, current = np.asarray(wind, float), np.asarray(current, float)

    def force(v):
        rel_w, rel_a = current - v, wind - v
        out = c_w * np.hypot(*rel_w) * rel_w + c_a * np.hypot(*rel_a) * rel_a
        out += -m * f * np.array([-v[1], v[0]])  # -m f k x v
        if tilt:
            out += m * f * np.array([-current[1], current[0]])
        return out / (c_w * 1e-2)

    guess = current + (wind - current) / (1.0 + math.sqrt(c_w / c_a))
    root = fsolve(force, guess, xtol=1e-14)
    # A root to round-off of the forces (scaled by 1 % of the water drag coefficient).
    assert np.max(np.abs(force(root))) < 1e-12, force(root)
    return root


def angle(a, b) -> float:
    """Angle from vector b to vector a, counter-clockwise (rad)."""
    return math.atan2(a[1] * b[0] - a[0] * b[1], a[0] * b[0] + a[1] * b[1])


def run_samples(world: World, steps: int, every: int):
    """Velocities (S, N, 2), positions (S, N, 2) and times (S,) every ``every`` steps."""
    vel, pos, t = [], [], []
    for _ in range(steps // every):
        world.advance(every)
        vel.append(world.velocities())
        pos.append(world.positions())
        t.append(world.time)
    world.check()
    return np.asarray(vel), np.asarray(pos), np.asarray(t)


# --------------------------------------------------------------------------------------------
# Current: the closed form of quadratic drag
# --------------------------------------------------------------------------------------------

CURRENT = 0.3 * np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
SMALL = (10.0, 1.0)  # side, thickness: m = 92 t, T = m / (c |u|) = 56 s


def current_error(dt: float) -> tuple[float, float]:
    """Worst error of the relative velocity and of the position against the closed form,
    a 10 m floe set free at rest in a uniform current for 20 T."""
    side, thick = SMALL
    m, c, _ = coefficients(side, thick)
    s = scene([floe(side)], thick, water={"current": CURRENT.tolist()})
    world = World([s], dt=dt, force_dt=True)
    assert world.layout.current and not (world.layout.wind or world.layout.coriolis)
    dv0 = -CURRENT  # v0 - u
    k = c * np.hypot(*dv0) / m  # 1 / T
    steps = round(20.0 / k / dt)
    vel, pos, t = run_samples(world, steps, max(steps // 40, 1))
    exact_v = CURRENT + dv0[None] / (1.0 + k * t)[:, None]
    exact_x = CURRENT[None] * t[:, None] + dv0[None] / k * np.log1p(k * t)[:, None]
    err_v = float(np.max(np.abs(vel[:, 0] - exact_v))) / float(np.hypot(*dv0))
    err_x = float(np.max(np.abs(pos[:, 0] - exact_x)))
    # The relative velocity falls to what the closed form says, never turning.
    rel = vel[:, 0] - CURRENT
    assert np.all(np.diff(np.hypot(rel[:, 0], rel[:, 1])) < 0.0)
    assert abs(angle(rel[-1], dv0)) < 1e-12
    return err_v, err_x


def test_a_floe_in_a_current_follows_the_closed_form_of_quadratic_drag(f64):
    """m dv/dt = -c |v - u| (v - u) from rest: v - u falls as 1 / (1 + c |u| t / m), to
    first order in dt."""
    side, thick = SMALL
    m, c, _ = coefficients(side, thick)
    k = c * np.hypot(*CURRENT) / m
    coarse, fine = 0.5, 0.25
    err_coarse, xerr_coarse = current_error(coarse)
    err_fine, xerr_fine = current_error(fine)
    print(
        f"max |v - v_exact| / |u| = {err_coarse:.3e} at dt = {coarse} s, {err_fine:.3e} at "
        f"{fine} s (dt / T = {coarse * k:.2e}); position error {xerr_coarse:.3e}, "
        f"{xerr_fine:.3e} m"
    )
    assert err_coarse <= EULER_BOUND * coarse * k
    assert HALVING_BAND[0] < err_fine / err_coarse < HALVING_BAND[1]
    assert HALVING_BAND[0] < xerr_fine / xerr_coarse < HALVING_BAND[1]


# --------------------------------------------------------------------------------------------
# Wind and Coriolis: free drift
# --------------------------------------------------------------------------------------------

BIG = (100.0, 2.0)  # side, thickness: m = 1.84e7 kg; the slowest relaxation ~1,350 s
WIND = np.array([10.0, 0.0])
DRIFT_DT, DRIFT_STEPS = 5.0, 8000  # 40,000 s: 30 of the slowest relaxation times


def test_free_drift_under_wind_balances_the_two_drags(f64):
    """Wind alone: the floe reaches s = U / (1 + sqrt(c_w / c_a)) along the wind (the
    quadratic air drag on the relative wind equals the water drag)."""
    side, thick = BIG
    _m, c_w, c_a = coefficients(side, thick)
    s = scene([floe(side)], thick, water={}, wind={"velocity": WIND.tolist()})
    world = World([s], dt=DRIFT_DT, force_dt=True)
    assert world.layout.wind and not (world.layout.current or world.layout.coriolis)
    start = budget.as_series(world.energies()[0].copy())
    world.advance(DRIFT_STEPS)
    world.check()
    v = world.velocities()[0]
    speed = float(np.hypot(*WIND)) / (1.0 + math.sqrt(c_w / c_a))
    print(f"free drift {np.hypot(*v):.12f} m/s, closed form {speed:.12f} m/s")
    assert np.hypot(*v) == pytest.approx(speed, rel=STEADY_RTOL)
    assert abs(angle(v, WIND)) < STEADY_RTOL
    now = budget.as_series(world.energies()[0])
    assert now["wind_work"] > 0.0 and now["current_work"] == 0.0
    assert abs(float(budget.residual(now, start))) < LONE_BUDGET_RTOL * now["wind_work"]


def test_wind_and_coriolis_turn_the_drift_to_the_right_in_the_north(f64):
    """Wind and Coriolis (f = 1.4e-4 1/s north, latitude 75 S): the steady drift's speed and
    its angle to the wind are the root of c_a |U - v| (U - v) - c_w |v| v - m f k x v = 0;
    to the right of the wind in the north, to the left by as much in the south."""
    side, thick = BIG
    m, c_w, c_a = coefficients(side, thick)
    wind = {"velocity": WIND.tolist()}
    north = scene([floe(side)], thick, water={}, wind=wind, coriolis={"f": 1.4e-4})
    south = scene([floe(side)], thick, water={}, wind=wind, coriolis={"latitude": -75.0})
    world = World([north, south], dt=DRIFT_DT, force_dt=True)
    world.advance(DRIFT_STEPS)
    world.check()
    v = world.velocities()
    f_south = 2.0 * 7.2921e-5 * math.sin(math.radians(-75.0))
    for got, f in zip(v, (1.4e-4, f_south)):
        want = steady_drift(m, c_w, c_a, f, WIND)
        print(
            f"f = {f:.4e}: speed {np.hypot(*got):.10f} (root {np.hypot(*want):.10f}) m/s, "
            f"angle {math.degrees(angle(got, WIND)):.8f} (root "
            f"{math.degrees(angle(want, WIND)):.8f}) degrees"
        )
        assert np.hypot(*got) == pytest.approx(np.hypot(*want), rel=STEADY_RTOL)
        assert angle(got, WIND) == pytest.approx(angle(want, WIND), abs=STEADY_RTOL)
    assert angle(v[0], WIND) < -0.05  # about 5 degrees to the right
    assert angle(v[1], WIND) > 0.05


# --------------------------------------------------------------------------------------------
# Current, wind, Coriolis and tilt together; the energy budget
# --------------------------------------------------------------------------------------------

GEO_CURRENT = np.array([0.1, 0.05])
FULL_DT, FULL_STEPS = 2.0, 20000


def full_scenes(thick_source: str = "full.toml"):
    """Two worlds of one floe in a geostrophic current at f = 1.4e-4: without wind (its air
    drag 0) and with wind."""
    side, thick = BIG
    tables = {
        "water": {"current": GEO_CURRENT.tolist(), "geostrophic": True},
        "coriolis": {"f": 1.4e-4},
    }
    calm = scene(
        [floe(side, velocity=(0.0, -0.1))],
        thick,
        wind={"velocity": [5.0, 0.0], "drag": 0.0},
        **tables,
    )
    windy = scene([floe(side)], thick, wind={"velocity": WIND.tolist()}, **tables)
    return [calm, windy]


def test_a_geostrophic_current_carries_a_floe_and_the_budget_closes(f64):
    """In a geostrophic current the tilt cancels Coriolis of the current, so the relative
    velocity w = v - u obeys m w' = -c |w| w - m f k x w: it turns at -f and falls as
    |w0| / (1 + c |w0| t / m). With wind the drift is the root of the whole balance. Both
    budgets close to round-off: Coriolis does no work."""
    side, thick = BIG
    m, c_w, c_a = coefficients(side, thick)
    world = World(full_scenes(), dt=FULL_DT, force_dt=True)
    layout = world.layout
    assert layout.current and layout.wind and layout.coriolis and layout.tilt
    start = budget.as_series(world.energies().copy())
    vel, _pos, t = run_samples(world, FULL_STEPS, 500)
    w0 = np.array([0.0, -0.1]) - GEO_CURRENT
    k = c_w * np.hypot(*w0) / m
    f = 1.4e-4
    turn = -f * t
    rot = np.stack([np.cos(turn), np.sin(turn)], axis=1)
    exact = np.stack([rot[:, 0] * w0[0] - rot[:, 1] * w0[1], rot[:, 1] * w0[0] + rot[:, 0] * w0[1]])
    exact = exact.T / (1.0 + k * t)[:, None]
    err = float(np.max(np.abs(vel[:, 0] - GEO_CURRENT - exact))) / float(np.hypot(*w0))
    print(f"geostrophic: max |w - w_exact| / |w0| = {err:.3e} (dt / T = {FULL_DT * k:.2e})")
    assert err <= EULER_BOUND * FULL_DT * k
    want = steady_drift(m, c_w, c_a, f, WIND, GEO_CURRENT, tilt=True)
    got = vel[-1, 1]
    print(f"windy: {got} m/s, root {want}")
    np.testing.assert_allclose(got, want, rtol=STEADY_RTOL, atol=STEADY_RTOL * np.hypot(*want))
    now = budget.as_series(world.energies())
    came = budget.came_in(now, start)
    res = budget.residual(now, start)
    print(f"budget residual / came in: {res / came}; terms {now}")
    assert np.all(np.abs(res) < LONE_BUDGET_RTOL * came)
    assert np.all(now["tilt_work"] != 0.0) and np.all(now["current_work"] != 0.0)
    assert now["wind_work"][0] == 0.0 and now["wind_work"][1] > 0.0


def test_drifting_floes_budget_closes_with_contacts(f64):
    """The bundled drifting scene (current, wind, Coriolis, tilt, a fixed island): the
    residual stays within the budget tests' bound while the floes collide."""
    s = load_scenario("drifting_floes")
    world = World([s])
    start = budget.as_series(world.energies().copy())
    every = round(0.5 / world.dt)
    worst, contacts = 0.0, 0
    for _ in range(16):  # 8 s
        world.advance(every)
        contacts += int(world.contact_counts()[0])
        now = budget.as_series(world.energies())
        came = float(budget.came_in(now, start)[0])
        worst = max(worst, abs(float(budget.residual(now, start)[0])) / came)
    world.check()
    print(f"worst residual / came in {worst:.3e}; contacts seen {contacts}; {now}")
    assert contacts > 0 and now["friction_energy"][0] > 0.0
    assert worst < CONTACT_BUDGET_RTOL
    for name in ("wind_work", "current_work", "tilt_work"):
        assert now[name][0] != 0.0, name


def test_forcing_runs_alike_alone_in_a_batch_and_stepped_by_bodies(f64):
    """Worlds of other currents, winds and f in one batch move as each alone, and stepping
    by bodies moves them as stepping by worlds, bit for bit."""
    scenes = full_scenes()
    raw = copy.deepcopy(dict(scenes[1].raw))
    raw["water"]["current"] = [-0.05, 0.02]
    raw["wind"]["velocity"] = [3.0, 7.0]
    raw["coriolis"] = {"latitude": 60.0}
    scenes.append(scene_from_dict(raw, source="other.toml"))
    batch = World(scenes, dt=FULL_DT, force_dt=True, stepping="worlds")
    bodies = World(scenes, dt=FULL_DT, force_dt=True, stepping="bodies")
    for w in (batch, bodies):
        w.advance(300)
    np.testing.assert_array_equal(batch.positions(), bodies.positions())
    np.testing.assert_array_equal(batch.velocities(), bodies.velocities())
    np.testing.assert_array_equal(batch.energies(), bodies.energies())
    want = batch.positions(), batch.velocities(), batch.energies()
    del batch, bodies  # a world alone has the batch's layout: it takes its kernels
    for k, s in enumerate(scenes):
        alone = World([s], dt=FULL_DT, force_dt=True, stepping="worlds")
        alone.advance(300)
        np.testing.assert_array_equal(alone.positions()[0], want[0][k])
        np.testing.assert_array_equal(alone.velocities()[0], want[1][k])
        np.testing.assert_array_equal(alone.energies()[0], want[2][k])
        del alone  # its fields and kernels serve the next World of its layout


# --------------------------------------------------------------------------------------------
# Gridded fields
# --------------------------------------------------------------------------------------------


def write_grid(path, u, v, x, y, t=None, units=None):
    """A netCDF grid of u, v (arrays (t,) y, x) on the coordinates x, y (and t); ``units``
    overrides the coordinates' units (``{"x": "degrees_east"}``)."""
    xr = pytest.importorskip("xarray")
    dims = ("y", "x") if t is None else ("t", "y", "x")
    coords = {"x": ("x", np.asarray(x, float)), "y": ("y", np.asarray(y, float))}
    if t is not None:
        coords["t"] = ("t", np.asarray(t, float))
    ds = xr.Dataset(
        {
            "uo": (dims, np.asarray(u, float), {"units": "m s-1"}),
            "vo": (dims, np.asarray(v, float), {"units": "m/s"}),
        },
        coords=coords,
    )
    ds["x"].attrs["units"] = "m"
    ds["y"].attrs["units"] = "m"
    for name, value in (units or {}).items():
        ds[name].attrs["units"] = value
    ds.to_netcdf(path)
    return path


GRID_X = np.array([-40.0, 0.0, 40.0, 80.0])
GRID_Y = np.array([-30.0, 0.0, 30.0, 60.0])


def grid_floes() -> list[dict]:
    """Floes far apart: inside the grid, on a node line, and beyond each of its edges."""
    places = [(13.0, 7.0), (40.0, -12.5), (-71.0, 22.0), (133.0, 95.0), (61.0, -88.0)]
    return [floe(SMALL[0], p, name=f"f{k}") for k, p in enumerate(places)]


def test_a_grid_of_one_value_runs_bit_for_bit_as_that_uniform_current(f64, tmp_path):
    """A current given on a grid whose nodes all hold (0.2, -0.1) moves floes inside and
    outside the grid exactly as the uniform current (0.2, -0.1): bit for bit."""
    gx, gy = np.meshgrid(GRID_X, GRID_Y)
    path = write_grid(tmp_path / "c.nc", 0.2 + 0 * gx, -0.1 + 0 * gy, GRID_X, GRID_Y)
    grid = {"current": {"file": str(path), "u": "uo", "v": "vo"}}
    gridded = scene(grid_floes(), SMALL[1], water=grid)
    uniform = scene(grid_floes(), SMALL[1], water={"current": [0.2, -0.1]})
    a, b = World([gridded], dt=0.5, force_dt=True), World([uniform], dt=0.5, force_dt=True)
    assert a.layout.current_grid and not b.layout.current_grid
    for w in (a, b):
        w.advance(400)
    np.testing.assert_array_equal(a.positions(), b.positions())
    np.testing.assert_array_equal(a.velocities(), b.velocities())
    np.testing.assert_array_equal(a.energies(), b.energies())


def test_grids_of_other_sizes_share_a_layout(tmp_path):
    """A grid's shape, origin and spacing are model data and its nodes a capacity (4,096 at
    least, ``assemble.CAPACITY_FLOORS``): scenes on a current grid of 4 x 4 nodes and one of
    7 x 5 compile one set of kernels; a grid past 4,096 nodes takes the next capacity."""
    from taichi_ice.engine.assemble import assemble

    def on_grid(nx, ny):
        x, y = np.linspace(-40.0, 80.0, nx), np.linspace(-30.0, 60.0, ny)
        gx, gy = np.meshgrid(x, y)
        path = write_grid(tmp_path / f"c{nx}x{ny}.nc", 0.1 + 0 * gx, 0 * gy, x, y)
        current = {"current": {"file": str(path), "u": "uo", "v": "vo"}}
        return assemble([scene(grid_floes(), SMALL[1], water=current)])

    small, other, large = on_grid(4, 4), on_grid(7, 5), on_grid(80, 60)
    assert small.layout.current_grid and small.real.grid_nodes == 16
    assert other.real.grid_nodes == 35 and other.layout == small.layout
    assert large.layout.grid_nodes == 5120 and large.layout != small.layout  # 4,800 nodes


def test_a_bilinear_current_is_sampled_exactly_at_the_centroid(f64, tmp_path):
    """u = (0.1 + 2e-3 x - 1e-3 y, -0.05 + 1e-3 y + 2e-5 x y) on the grid: one step from rest
    gives each floe dt c |u| u / m with u at its centroid, clamped to the grid beyond it."""
    gx, gy = np.meshgrid(GRID_X, GRID_Y)

    def field(x, y):
        return np.array([0.1 + 2e-3 * x - 1e-3 * y, -0.05 + 1e-3 * y + 2e-5 * x * y])

    u, v = field(gx, gy)
    path = write_grid(tmp_path / "c.nc", u, v, GRID_X, GRID_Y)
    s = scene(grid_floes(), SMALL[1], water={"current": {"file": str(path), "u": "uo", "v": "vo"}})
    dt = 0.5
    world = World([s], dt=dt, force_dt=True)
    world.step()
    m, c, _ = coefficients(*SMALL)
    for k, body in enumerate(s.bodies):
        x = np.clip(body.position[0], GRID_X[0], GRID_X[-1])
        y = np.clip(body.position[1], GRID_Y[0], GRID_Y[-1])
        at = field(x, y)
        want = dt * c * np.hypot(*at) * at / m
        np.testing.assert_allclose(world.velocities()[k], want, rtol=1e-12, err_msg=body.name)


def test_a_wind_grid_in_space_and_time_matches_the_numpy_twin(f64, tmp_path):
    """A wind on x, y and t (with a uniform geostrophic current and Coriolis): every floe
    follows the NumPy step, which samples the grid at the step's start, for 200 steps."""
    t = np.array([0.0, 40.0, 80.0])
    gt, gy, gx = np.meshgrid(t, GRID_Y, GRID_X, indexing="ij")
    u = 8.0 + 0.05 * gx - 0.03 * gy + 0.1 * gt + 0.001 * gx * gt
    v = -2.0 + 0.02 * gy * np.sin(gt / 30.0)
    path = write_grid(tmp_path / "w.nc", u, v, GRID_X, GRID_Y, t, units={"t": "s"})
    s = scene(
        grid_floes(),
        SMALL[1],
        water={"current": [0.05, 0.0], "geostrophic": True},
        wind={"velocity": {"file": str(path), "u": "uo", "v": "vo"}},
        coriolis={"latitude": 80.0},
    )
    dt = 0.5
    world = World([s], dt=dt, force_dt=True)
    assert world.layout.wind_grid and world.layout.clock
    model = ReferenceModel.from_batch(world.batch)
    state = ReferenceState.from_batch(world.batch)
    for _ in range(200):  # 100 s: past the grid's last time, where it is held
        world.step()
        state = reference_step(state, model, dt)
    np.testing.assert_allclose(world.velocities(), state.vel, rtol=TWIN_RTOL, atol=1e-14)
    np.testing.assert_allclose(world.positions(), state.pos, rtol=TWIN_RTOL)
    want = reference_energies(state, model)
    assert np.all(want[0, 8:] != 0.0)  # the wind's, the current's and the tilt's work
    np.testing.assert_allclose(world.energies(), want, rtol=TWIN_RTOL, atol=1e-9)


def test_grid_sample_is_exact_for_a_trilinear_field():
    """The NumPy sampler reproduces a field bilinear in x, y and linear in t exactly, and
    holds it constant beyond every end."""
    rng = np.random.default_rng(7)
    x = -5.0 + 2.5 * np.arange(5)
    y = 3.0 + 4.0 * np.arange(4)
    t = 10.0 * np.arange(3)
    gt, gy, gx = np.meshgrid(t, y, x, indexing="ij")

    def field(tt, yy, xx):
        return np.stack(
            [
                1.0 + 0.3 * xx - 0.2 * yy + 0.01 * xx * yy + 0.05 * tt * (1 + 0.1 * xx),
                0.5 * tt + yy,
            ],
            axis=-1,
        )

    values = field(gt, gy, gx)
    for _ in range(200):
        px, py, pt = rng.uniform(-15, 25), rng.uniform(-5, 25), rng.uniform(-10, 30)
        got = forcing.grid_sample(values, (x[0], y[0], t[0]), (2.5, 4.0, 10.0), px, py, pt)
        want = field(np.clip(pt, t[0], t[-1]), np.clip(py, y[0], y[-1]), np.clip(px, x[0], x[-1]))
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)


# --------------------------------------------------------------------------------------------
# No forcing: as before
# --------------------------------------------------------------------------------------------


def test_a_still_current_runs_bit_for_bit_as_still_water(f64):
    """Two squares colliding in water move the same with current = [0, 0] as without one:
    the forcing's path of the step reduces to the old one bit for bit (and a scene without
    forcing compiles none of it: Layout.current is off)."""
    base = copy.deepcopy(dict(load_scenario("two_squares").raw))
    base["water"] = {}
    still = scene_from_dict(base, source="still.toml")
    base["water"] = {"current": [0.0, 0.0]}
    zero = scene_from_dict(base, source="zero.toml")
    a, b = World([still]), World([zero])
    assert not a.layout.current and b.layout.current
    for w in (a, b):
        w.advance(round(0.4 / a.dt))  # the faces, 0.2 m apart, meet at 1 m/s after 0.2 s
    assert int(a.contact_counts()[0]) + float(a.energies()[0, 1]) > 0  # they met
    np.testing.assert_array_equal(a.positions(), b.positions())
    np.testing.assert_array_equal(a.velocities(), b.velocities())
    np.testing.assert_array_equal(a.omegas(), b.omegas())
    np.testing.assert_array_equal(a.energies()[:, :8], b.energies()[:, :8])
    assert np.all(b.energies()[:, 8:] == 0.0)


# --------------------------------------------------------------------------------------------
# The Taichi functions against their NumPy twins
# --------------------------------------------------------------------------------------------


@ti.kernel
def _forcing_each(inputs: ti.types.ndarray(ndim=2), out: ti.types.ndarray(ndim=2)):
    for i in range(inputs.shape[0]):
        vel = ti.Vector([inputs[i, 0], inputs[i, 1]], ti.f64)
        wind = ti.Vector([inputs[i, 2], inputs[i, 3]], ti.f64)
        accel = ti.Vector([inputs[i, 4], inputs[i, 5]], ti.f64)
        c_air, f, dt = inputs[i, 6], inputs[i, 7], inputs[i, 8]
        fa = forcing_ti.air_drag_ti(vel, wind, c_air)
        v1 = forcing_ti.coriolis_step_ti(vel, accel, f, dt)
        tilt = forcing_ti.tilt_acceleration_ti(f, wind)
        i0, i1, w = forcing_ti.grid_cell_ti(inputs[i, 9], ti.cast(inputs[i, 10], ti.i32))
        out[i, 0], out[i, 1] = fa[0], fa[1]
        out[i, 2], out[i, 3] = v1[0], v1[1]
        out[i, 4], out[i, 5] = tilt[0], tilt[1]
        out[i, 6], out[i, 7], out[i, 8] = ti.cast(i0, ti.f64), ti.cast(i1, ti.f64), w


def test_taichi_forcing_functions_equal_their_numpy_twins(taichi_runtime):
    """Air drag, the Coriolis step, the tilt and the grid cell on 2,000 seeded inputs; the
    Coriolis step does no work (its force is perpendicular to the mean velocity)."""
    rng = np.random.default_rng(32)
    n = 2000
    inputs = np.column_stack(
        [
            rng.normal(0, 0.5, (n, 2)),  # vel
            rng.normal(0, 10.0, (n, 2)),  # wind (and current for the tilt)
            rng.normal(0, 1e-3, (n, 2)),  # accel
            rng.uniform(0, 50.0, n),  # c_air
            rng.uniform(-1.5e-4, 1.5e-4, n) * rng.choice([1.0, 1e3], n),  # f
            rng.uniform(1e-3, 100.0, n),  # dt
            rng.uniform(-3.0, 12.0, n),  # fractional index
            rng.integers(1, 9, n).astype(float),  # nodes
        ]
    )
    out = np.zeros((n, 9))
    _forcing_each(inputs, out)
    f64 = taichi_runtime[1] == "f64"
    rtol = 1e-14 if f64 else 1e-5
    for row, got in zip(inputs, out):
        vel, wind, accel = row[0:2], row[2:4], row[4:6]
        c_air, f, dt = row[6:9]
        np.testing.assert_allclose(got[0:2], forcing.air_drag(vel, wind, c_air), rtol=rtol)
        v1 = forcing.coriolis_step(vel, accel, f, dt)
        np.testing.assert_allclose(got[2:4], v1, rtol=rtol, atol=rtol * np.abs(v1).max())
        np.testing.assert_allclose(got[4:6], forcing.tilt_acceleration(f, wind), rtol=rtol)
        np.testing.assert_allclose(got[6:9], forcing.grid_cell(row[9], int(row[10])), atol=1e-15)
        # Coriolis does no work: the kinetic energy changes by the work of accel alone, at
        # the step's mean velocity; with no other force the speed stays.
        vm = 0.5 * (vel + v1)
        gain = 0.5 * (v1 @ v1 - vel @ vel) - dt * (accel @ vm)
        assert abs(gain) <= 1e-13 * (v1 @ v1 + vel @ vel)
        spun = forcing.coriolis_step(vel, np.zeros(2), f, dt)
        assert np.hypot(*spun) == pytest.approx(np.hypot(*vel), rel=1e-13)


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


def bad_scene(tmp_path, **tables):
    return scene([floe(10.0)], 1.0, source=str(tmp_path / "bad.toml"), **tables)


GRID_ERRORS = [
    # (what the grid file does wrong, key named, words of the message)
    ("no_variable", "u", "has no variable 'uo'"),
    ("lonlat", "u", "dimensions"),
    ("uneven", "file", "not evenly spaced"),
    ("decreasing", "file", "not increasing"),
    ("nan", "u", "non-finite"),
    ("degrees", "file", "give it in m"),
    ("no_coordinate", "file", "no coordinate variable"),
    ("missing_file", "file", "cannot read"),
    ("not_netcdf", "file", "cannot read"),
]


@pytest.mark.parametrize(("case", "key", "words"), GRID_ERRORS, ids=[c[0] for c in GRID_ERRORS])
def test_bad_grid_files_are_refused_naming_file_table_key_and_variable(tmp_path, case, key, words):
    """Each fault of a grid file: a ScenarioError naming the scene file, [water] current,
    the key and the netCDF file."""
    xr = pytest.importorskip("xarray")
    path = tmp_path / "c.nc"
    gx, gy = np.meshgrid(GRID_X, GRID_Y)
    u, v = 0.1 + 0 * gx, 0 * gy
    names = ("uo", "vo")
    if case == "no_variable":
        write_grid(path, u, v, GRID_X, GRID_Y)
        names = ("uo", "vo")
        ds = xr.open_dataset(path).rename({"uo": "u_east"}).load()
        ds.to_netcdf(tmp_path / "c2.nc")
        path = tmp_path / "c2.nc"
    elif case == "lonlat":
        xr.Dataset(
            {"uo": (("lat", "lon"), u), "vo": (("lat", "lon"), v)},
            coords={"lon": GRID_X, "lat": GRID_Y},
        ).to_netcdf(path)
    elif case == "uneven":
        write_grid(path, u, v, [-40.0, 0.0, 45.0, 80.0], GRID_Y)
    elif case == "decreasing":
        write_grid(path, u, v, GRID_X[::-1], GRID_Y)
    elif case == "nan":
        u = u.copy()
        u[1, 2] = np.nan
        write_grid(path, u, v, GRID_X, GRID_Y)
    elif case == "degrees":
        write_grid(path, u, v, GRID_X, GRID_Y, units={"x": "degrees_east"})
    elif case == "no_coordinate":
        xr.Dataset({"uo": (("y", "x"), u), "vo": (("y", "x"), v)}).to_netcdf(path)
    elif case == "not_netcdf":
        path.write_text("not a netCDF file\n")
    table = {"file": str(path), "u": names[0], "v": names[1]}
    with pytest.raises(ScenarioError) as info:
        bad_scene(tmp_path, water={"current": table})
    message = str(info.value)
    print(message)
    assert message.startswith(f"{tmp_path / 'bad.toml'}: [water] current, key '{key}': ")
    assert words in message and "\n" not in message
    if case != "missing_file":
        assert str(path) in message


TABLE_ERRORS = [
    ({"water": {"current": "fast"}}, "[water], key 'current'", "expected [u, v]"),
    ({"water": {"current": [0.1]}}, "[water], key 'current'", "two numbers"),
    ({"water": {"current": {"path": "c.nc"}}}, "[water] current", "unknown key 'path'"),
    ({"water": {"current": [0.1, 0.0], "geostrophic": True}}, "'geostrophic'", "[coriolis]"),
    ({"water": {"geostrophic": True}, "coriolis": {"f": 1e-4}}, "'geostrophic'", "a current"),
    ({"coriolis": {"f": 1e-4, "latitude": 70.0}}, "[coriolis]", "one of the two"),
    ({"coriolis": {}}, "[coriolis]", "one of the two"),
    ({"coriolis": {"latitude": 95.0}}, "[coriolis], key 'latitude'", "[-90, 90]"),
    ({"coriolis": {"f": "1e-4"}}, "[coriolis], key 'f'", "remove the quotes"),
    ({"wind": {}}, "[wind], key 'velocity'", "required"),
    ({"wind": {"velocity": [5.0, 0.0], "drag": -1e-3}}, "[wind], key 'drag'", "negative"),
    ({"wind": {"velocity": [5.0, 0.0], "air_density": 0.0}}, "'air_density'", "positive"),
    ({"wind": {"velocity": [5.0, 0.0], "speed": 3.0}}, "[wind]", "unknown key 'speed'"),
    ({"wind": {"velocity": [float("nan"), 0.0]}}, "[wind], key 'velocity'", "finite"),
]


@pytest.mark.parametrize(("tables", "where", "words"), TABLE_ERRORS)
def test_bad_forcing_keys_are_refused_with_a_clear_message(tmp_path, tables, where, words):
    """Bad values and keys of [water] current, [wind] and [coriolis]: one line naming the
    file, the table and the key."""
    with pytest.raises(ScenarioError) as info:
        bad_scene(tmp_path, **tables)
    message = str(info.value)
    print(message)
    assert message.startswith(f"{tmp_path / 'bad.toml'}: ")
    assert where in message and words in message and "\n" not in message


def test_a_batch_refuses_worlds_of_other_forcing(tmp_path):
    """Worlds with and without wind or Coriolis, or on other grids, cannot share the
    compiled step; worlds of other uniform values can."""
    from taichi_ice.engine.assemble import assemble

    base = {"water": {"current": [0.1, 0.0]}}
    a = bad_scene(tmp_path, **base)
    windy = bad_scene(tmp_path, wind={"velocity": [1.0, 2.0]}, **base)
    turning = bad_scene(tmp_path, coriolis={"f": 1e-4}, **base)
    other = bad_scene(tmp_path, water={"current": [0.0, -0.2]})
    assemble([a, other])  # other uniform currents: one batch
    for b, words in ((windy, "[wind]"), (turning, "[coriolis]")):
        with pytest.raises(ValueError, match="world 1") as info:
            assemble([a, b])
        assert words in str(info.value)
    gx, gy = np.meshgrid(GRID_X, GRID_Y)
    grids = []
    for k, value in enumerate((0.1, 0.2)):
        path = write_grid(tmp_path / f"g{k}.nc", value + 0 * gx, 0 * gy, GRID_X, GRID_Y)
        table = {"current": {"file": str(path), "u": "uo", "v": "vo"}}
        grids.append(bad_scene(tmp_path, water=table))
    with pytest.raises(ValueError, match=r"\[water\]"):
        assemble(grids)
    with pytest.raises(ValueError, match=r"\[water\]"):
        assemble([a, grids[0]])
