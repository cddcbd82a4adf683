"""What happens at every contact: one row per contact of a World's state, for run files.

``contact_rows(world)`` returns, for each world of the batch, the contacts of **the step that
starts now** (at a frame, the step that starts at the frame's time): for each pair in
contact, the two bodies, the contact point, normal, width and overlap, the normal and
tangential force, the friction coefficient, the slip rate, theta and whether the contact
sticks. The forces are those the engine applies over that step, ``(t, t + dt]``: summed
over a body's rows they are the body's net contact force of the step (``body_force_q``),
over the probes' rows the probe force of the step; theta and the slip rate are what the
step leaves in the contact's slot (``contact_theta``, ``contact_slip``). The midstep step
(Coulomb friction's default integrator) takes each contact at the pose predicted for
mid-step, every body in free flight for dt / 2 from the frame: there a row's point, normal,
width and overlap are that pose's (the frame's where the outlines no longer overlap then),
and the force's torque on a body is about its centroid at that pose, ``position + dt / 2
velocity``.

How: the rows are computed on the host from the state read back (positions, the bodies'
rotations ``body_rot``, velocities, each contact slot's memory: partner, stretch, theta,
slip rate, crushed area, the analytic step's last forces; the last velocity changes; for the
midstep step the angles, which turn each body to its predicted mid-step pose) by the
contact kernel's NumPy twin, ``reference_contact.contact_force``, which does the kernel's
float64 operations in the same order (``tests/test_engine.py`` holds whole runs of them
together): equal to what the kernel applies to round-off in a float64 run, to float32's
round-off in a float32 run (the twin works in float64). The kernel is not changed and stores
nothing more, so a run that asks for rows steps bit for bit as one that does not, compiles
no other kernels, and the geometry of a frame's rows is that of the frame's own positions
(the midstep step's: of the pose it predicts from them; the first frame, t = 0, has its rows
too). The price is host time: about 0.2 ms of Python
per contact per frame (a pillar scene's 100 contacts, 20 ms a frame); a field of 1e4 floes
spends seconds a frame on it. (Storing the rows in the kernel, fields compiled in on
demand, is the way for large fields on a GPU: not done.)

Pairs: the bodies' bounding circles are swept along x (NumPy, a world at a time), a pair
beyond a face of either outline is dropped, and each pair left is handed to the twin with
the body that owns it in the kernel as the first (``ContactLists.wants``: a small dynamic
body owns its contacts with bodies that are not dynamic and with dynamic ones of higher id;
a small body its contacts with large ones; large bodies among themselves the lower id), so
that its slot memory is found and the normal runs the kernel's way, from ``body_a`` (the
owner) into ``body_b``. The force of a row is on ``body_b``; ``body_a`` takes its opposite.

NumPy only (it reads the World's fields with ``to_numpy``; no kernel is compiled).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..codes import BodyKind
from ..physics.slip import NO_INTERFACE_ABOVE
from .reference import ReferenceModel, outline
from .reference_contact import ContactMemory, contact_force

__all__ = ["ROW_NAMES", "candidate_pairs", "contact_rows", "empty_rows"]

# The columns of a row, in the run file's order (``runfile.VARIABLES["contacts"]``).
ROW_NAMES = (
    "body_a",
    "body_b",
    "point",
    "normal",
    "width",
    "overlap",
    "force_normal",
    "force_tangential",
    "slip_rate",
    "theta",
    "mu",
    "stuck",
)
# The bounding-circle test keeps a pair whose circles come within this share of their radii:
# a superset of the kernel's (whose reach is rounded at the run's precision); the twin's
# clip drops a pair that does not overlap.
REACH_MARGIN = 1e-6


def empty_rows(n: int = 0) -> dict[str, np.ndarray]:
    """Rows of ``n`` contacts, zero-filled, of the run file's types and shapes."""
    out = {}
    for name in ROW_NAMES:
        if name in ("body_a", "body_b"):
            out[name] = np.zeros(n, dtype=np.int64)
        elif name == "stuck":
            out[name] = np.zeros(n, dtype=np.int8)
        elif name in ("point", "normal"):
            out[name] = np.zeros((n, 2))
        else:
            out[name] = np.zeros(n)
    return out


def candidate_pairs(pos: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)``, ``i < j``, of bodies whose bounding circles meet (indices into
    ``pos`` ``(N, 2)`` and ``radius`` ``(N,)``, m): a sweep along x, then the circles."""
    n = len(radius)
    if n < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    lo = pos[:, 0] - radius
    order = np.argsort(lo, kind="stable")
    lo_sorted = lo[order]
    hi_sorted = (pos[:, 0] + radius)[order]
    # Sorted position k meets every later one whose interval starts before k's ends.
    end = np.searchsorted(lo_sorted, hi_sorted, side="right")
    counts = np.maximum(end - np.arange(n) - 1, 0)
    first = np.repeat(np.arange(n), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    a, b = order[first], order[first + 1 + offset]
    d = pos[b] - pos[a]
    reach = (radius[a] + radius[b]) * (1.0 + REACH_MARGIN)
    keep = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] < reach * reach
    a, b = a[keep], b[keep]
    return np.minimum(a, b), np.maximum(a, b)


def _beyond_a_face(centre, radius, outline, normals, count) -> np.ndarray:
    """``(P,)``: circle ``centre`` ``(P, 2)``, ``radius`` ``(P,)`` lies wholly outside a face of
    the outlines ``(P, V, 2)`` (outward unit normals ``(P, V, 2)``, ``count`` ``(P,)`` vertices
    in use): the pair cannot overlap (``ContactLists.beyond_a_face``)."""
    reach = np.einsum("pvk,pvk->pv", centre[:, None, :] - outline, normals)
    used = np.arange(outline.shape[1])[None, :] < count[:, None]
    return np.any(used & (reach > radius[:, None]), axis=1)


def _owner_first(kind, small, i, j) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``(i, j)`` as the kernel handles them, ``(owner, partner)``, and which of
    them any body handles at all (two bodies that cannot move have no contact)."""
    dyn_i, dyn_j = kind[i] == BodyKind.DYNAMIC, kind[j] == BodyKind.DYNAMIC
    small_i, small_j = small[i] != 0, small[j] != 0
    # ContactLists.wants(i, j), with i < j here.
    i_small_pair = (dyn_i & ~dyn_j) | (dyn_i & dyn_j)
    j_small_pair = dyn_j & ~dyn_i
    either = dyn_i | dyn_j
    i_owns = np.where(
        small_i & small_j, i_small_pair, np.where(small_i != small_j, small_i & either, either)
    )
    j_owns = np.where(
        small_i & small_j, j_small_pair, np.where(small_i != small_j, small_j & either, False)
    )
    owner = np.where(i_owns, i, j)
    partner = np.where(i_owns, j, i)
    return owner, partner, i_owns | j_owns


def _outlines(model: ReferenceModel, rot: np.ndarray, max_verts: int):
    """Every body's outline relative to its centroid, turned by its rotation as the kernel
    turns it (``ContactLists.turned``: ``c x - s y``, ``s x + c y``), padded to ``max_verts``
    ``(N, V, 2)``, the outward unit normals of its edges ``(N, V, 2)`` and the counts."""
    n = model.n_bodies
    verts = np.zeros((n, max_verts, 2))
    count = np.array([len(v) for v in model.vertices], dtype=np.int64)
    for i, v in enumerate(model.vertices):
        verts[i, : len(v)] = v
    c, s = rot[:, 0:1], rot[:, 1:2]
    turned = np.stack(
        [c * verts[..., 0] - s * verts[..., 1], s * verts[..., 0] + c * verts[..., 1]], axis=-1
    )
    k = np.arange(max_verts)[None, :]
    nxt = np.where(k + 1 < count[:, None], k + 1, 0)  # each edge from vertex k to the next
    edge = turned[np.arange(n)[:, None], nxt] - turned
    length = np.hypot(edge[..., 0], edge[..., 1])
    length[length == 0.0] = 1.0
    normals = np.stack([edge[..., 1], -edge[..., 0]], axis=-1) / length[..., None]
    return turned, normals, count


def _read(world) -> dict:
    """The state the contact stage reads at the start of a step, as float64 host arrays."""
    layout, n = world.layout, world.batch.n_bodies
    names = {  # key: (field, a real to float64)
        "pos": ("body_pos", True),
        "rot": ("body_rot", True),
        "vel": ("body_vel", True),
        "omega": ("body_omega", True),
        "count": ("contact_count", False),
        "partner": ("contact_partner", False),
        "xi": ("contact_xi", True),
    }
    if layout.rate_state:
        names["theta"], names["slip"] = ("contact_theta", True), ("contact_slip", True)
    if layout.crushing:
        names["crushed"] = ("contact_crushed", True)
    if layout.analytic:
        names["force"] = ("contact_force", True)
    if layout.midstep:  # the step's mid-step configuration turns each body by its angle
        names["angle"] = ("body_angle", True)
    if layout.velocity_changes:
        names["dvel"], names["domega"] = ("body_dvel", True), ("body_domega", True)
    # One launch for all of them (``World.read``), not a to_numpy kernel per field.
    got = world.read([field for field, _ in names.values()])
    out = {}
    for key, (field, real) in names.items():
        a = got[field][:n]
        out[key] = a.astype(np.float64) if real else a
    if not layout.velocity_changes:
        out["dvel"], out["domega"] = np.zeros((n, 2)), np.zeros(n)
    return out


def _memory(state: dict, owner: int, slot: int) -> ContactMemory:
    """The memory the kernel reads from slot ``slot`` of ``owner``."""
    kw = {"xi": float(state["xi"][owner, slot])}
    if "theta" in state:
        kw["theta"] = float(state["theta"][owner, slot])
        kw["slip"] = float(state["slip"][owner, slot])
    if "crushed" in state:
        kw["crushed"] = float(state["crushed"][owner, slot])
    if "force" in state:
        kw["force"] = tuple(float(f) for f in state["force"][owner, slot])
    return ContactMemory(**kw)


def contact_rows(world) -> list[dict[str, np.ndarray]]:
    """Every contact of every world of ``world`` (an ``engine.world.World``) in the step that
    starts now: one dict of ``ROW_NAMES`` arrays per world, bodies numbered within the world.

    Rows (one per pair in contact, in the order of their owners and partners):
        body_a, body_b: the pair; ``body_a`` owns the contact in the kernel.
        point ``(K, 2)``: the overlap's centroid in the world (m). normal ``(K, 2)``: unit,
        from ``body_a`` into ``body_b``. width: the chord ``L`` (m). overlap: the overlap's
        area (m^2; crushed area included).
        force_normal (N, >= 0) and force_tangential (N): the force on ``body_b`` along
        ``normal`` and along the tangent ``(-normal_y, normal_x)``; ``body_a`` takes the
        opposite: the step's mean where a sliding rate-and-state contact took its step in
        sub-steps (``[ice] slide_resolution``). mu: the friction coefficient of the step (the
        mean over its sub-steps: the force is ``mu F_n`` where the contact slid through the
        whole step, below it where its slide started or stopped within the step).
        slip_rate: the rate the surfaces slide at along the tangent (m/s, signed; 0 if
        stuck): the law's V in a rate-and-state batch (that of the last sub-step, the rate
        the step leaves, as theta), else the slide of the step that the
        stick spring does not take up, over dt. theta: the rate-and-state variable the step
        leaves (dimensionless), NaN for a Coulomb world and for a contact with no sliding
        interface. stuck: 1 if the tangential force is the stick spring-dashpot's (below
        ``mu F_n``), 0 if it slides (capped at ``mu F_n``; in sub-steps, if its last one slid).
    """
    layout = world.layout
    model = ReferenceModel.from_batch(world.batch)
    host = world.batch.host
    state = _read(world)
    pos = state["pos"]
    turned, normals, count = _outlines(model, state["rot"], layout.max_verts)
    radius = np.asarray(host.body_radius, dtype=np.float64)
    slot_of = {
        (int(o), int(state["partner"][o, s])): int(s)
        for o, s in zip(*np.nonzero(np.arange(state["partner"].shape[1]) < state["count"][:, None]))
    }
    # The midstep step linearises each contact about the configuration predicted for
    # mid-step (every body in free flight for dt / 2), as ``reference.reference_step`` does.
    mid = None
    if model.midstep:
        half = 0.5 * float(world.dt)
        mid = SimpleNamespace(
            pos=pos + half * state["vel"], angle=state["angle"] + half * state["omega"]
        )
    out = []
    for sl in world.batch.world_slices():
        i, j = candidate_pairs(pos[sl], radius[sl])
        i, j = i + sl.start, j + sl.start
        owner, partner, handled = _owner_first(host.body_kind, host.body_small, i, j)
        owner, partner = owner[handled], partner[handled]
        # Outlines relative to each pair's owner, and the circles against the other's faces.
        rel = pos[partner] - pos[owner]
        apart = _beyond_a_face(
            rel, radius[partner], turned[owner], normals[owner], count[owner]
        ) | _beyond_a_face(-rel, radius[owner], turned[partner], normals[partner], count[partner])
        owner, partner = owner[~apart], partner[~apart]
        order = np.lexsort((partner, owner))
        rows = []
        for o, p in zip(owner[order].tolist(), partner[order].tolist()):
            slot = slot_of.get((o, p))
            memory = None if slot is None else _memory(state, o, slot)
            origin = pos[o]
            shift = pos[p] - origin
            at_mid = None
            if mid is not None:
                at_mid = (
                    outline(model, mid, o, origin),
                    outline(model, mid, p, origin),
                    mid.pos[o] - origin,
                    mid.pos[p] - origin,
                )
            c = contact_force(
                turned[o, : count[o]],
                shift + turned[p, : count[p]],
                np.zeros(2),
                state["vel"][o],
                float(state["omega"][o]),
                shift,
                state["vel"][p],
                float(state["omega"][p]),
                dt=float(world.dt),
                dvel=(state["dvel"][o], state["dvel"][p]),
                domega=(float(state["domega"][o]), float(state["domega"][p])),
                memory=memory,
                mid=at_mid,
                **model.pair(o, p),
            )
            if c is None:
                continue
            rows.append((o, p, origin, c, memory))
        out.append(_tabulate(rows, sl.start, layout.rate_state, model, world.dt))
    return out


def _tabulate(rows, start: int, rate_state: bool, model: ReferenceModel, dt: float) -> dict:
    """The rows of one world as arrays (``ROW_NAMES``)."""
    table = empty_rows(len(rows))
    for k, (o, p, origin, c, memory) in enumerate(rows):
        table["body_a"][k], table["body_b"][k] = o - start, p - start
        table["point"][k] = origin + c.point
        table["normal"][k] = c.normal
        # The overlap of the pose the step takes the contact at (the mid-step pose's with
        # the midstep step), as its point, normal and width.
        table["width"][k], table["overlap"][k] = c.width, c.step_area
        table["force_normal"][k], table["force_tangential"][k] = c.normal_force, c.tangential_force
        table["mu"][k] = c.mu
        table["stuck"][k] = 0 if c.sliding else 1
        law = model.laws[int(model.world[o])]
        theta = np.nan
        if rate_state:
            table["slip_rate"][k] = c.sliding_rate
            remembers = not isinstance(law, float) and law.get("memory", 1)
            if remembers and c.memory.theta < NO_INTERFACE_ABOVE:
                theta = c.memory.theta
        elif c.sliding:
            # The slide the stick spring does not take up (``contact_law.tangential_force``).
            xi = 0.0 if memory is None else memory.xi
            table["slip_rate"][k] = (xi + c.slip * dt - c.memory.xi) / dt
        table["theta"][k] = theta
    return table
