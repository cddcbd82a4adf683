"""The half of the contact stage that finds candidate pairs: outlines, ownership, neighbour lists.

``ContactLists`` is the base of ``contact.ContactStage``: the Taichi functions that turn a
body's shape into place (``outline``, ``normals``), decide which body of a pair handles it
(``wants``: the ownership rules told in ``contact``), cheaply reject pairs that cannot touch
(``near``, ``beyond_a_face``, ``gap_bound``), and rebuild each body's neighbour list from the
spatial hash (the kernel ``build_lists``); and the small pieces of a pair's contact the
stage's ``pair`` calls (``relative`` velocities, ``midstep_outlines``, the gathers
``add_force`` and ``add_shift``, ``remember``: a body's contact memory copied out of its
slots); and ``settle`` (the kernel ``settle_all``), which books the analytic steps'
contact work again once the bodies have moved. The forces of the pairs found, and the
contacts' memory, are ``contact.ContactStage``'s; it declares what both halves' kernels read
and write (``ContactStage.ACCESS``).
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

import taichi as ti

from .. import backend
from ..codes import BodyEnergy, BodyKind, Status
from ..physics.contact_law_ti import perp
from ..physics.polygon_ti import overlap_normals_ti, rotation_ti
from .broadphase import bucket_of
from .gather import gather
from .stages import Access, Stage

# The midstep step clips a touching pair twice, at the step's start and at mid-step. For
# outlines of up to this many vertices (``Layout.max_verts``) the kernel inlines the clip
# twice; for larger ones it calls it once, in a loop over the two poses (``step_overlaps``).
SHARED_CLIP_VERTS = 4

# Round-off allowance of a gap that lets a pair be skipped (``ContactStage.gap_bound``), as
# a fraction of the two circumradii: 1e-5 m for two of the paper's diamonds, against ~1e-7 m
# of error in a float32 outline a metre across, turned and shifted relative to the pair.
GAP_MARGIN = 1e-5

# What ``ContactLists.settle_all`` reads and writes (``ContactStage.ACCESS``): a contact's
# slot, its bodies' velocity changes and the owner's energy rows, per contact.
_SETTLE_PER_CONTACT = (
    "contact_partner",
    "contact_booking",
    "contact_elastic",
    "body_dvel",
    "body_domega",
    "body_energy",
)
SETTLE_ACCESS = Access(
    reads=("body_count", "contact_count", *_SETTLE_PER_CONTACT),
    writes=("contact_elastic", "body_energy"),
    per_contact=_SETTLE_PER_CONTACT,
)


@ti.data_oriented
class ContactLists(Stage):
    """Candidate pairs of the contact stage: outlines turned into place, pair ownership and
    the neighbour lists. Holds no state of its own: ``ContactStage.__init__`` sets the
    layout, fields, spatial hash and neighbour lists these read."""

    @ti.func
    def outline(self, i, origin):
        """Body i's outline relative to ``origin`` in a (MAXV, 2) matrix, and its count.

        Positions are float64 in either precision and only their difference is cast to
        the run's precision: clipping near the pair keeps float32 accurate in large fields,
        its resolution scaling with the bodies' size, not the domain's.
        The outline is the body's shape (``vert_local``, shared by bodies of one shape, so
        it stays in cache) turned by its rotation (``body_rot``, the integrator's cos and
        sin): four multiply-adds a vertex instead of a turned outline stored per body.
        """
        m, d = ti.static((self.model, self.data))
        x = ti.cast(d.body_pos[i] - origin, self.layout.real)  # positions are f64
        return self.turned(i, m.vert_local, x, True), m.body_vert_count[i]

    @ti.func
    def normals(self, i):
        """Outward unit normals of body i's edges in a (MAXV, 2) matrix: its shape's
        (``vert_normal_local``) turned by its rotation, as ``outline`` turns the vertices
        (``polygon_ti.edge_normals_ti`` of the outline, without a square root an edge)."""
        zero = ti.Vector([0.0, 0.0], self.layout.real)
        return self.turned(i, self.model.vert_normal_local, zero, False)

    @ti.func
    def turned(self, i, local: ti.template(), shift, shifted: ti.template()):
        """Rows of body i's shape in ``local`` (a field of 2-vectors indexed like
        ``vert_local``) turned by the body's rotation, plus ``shift`` if ``shifted``, in a
        (MAXV, 2) matrix. Unrolled to the largest outline, so that the matrix's indices are
        constants (``polygon_ti._min_penetration_axis_ti`` says why)."""
        rot = self.data.body_rot[i]
        return self.turned_by(i, local, shift, shifted, rot[0], rot[1])

    @ti.func
    def turned_by(self, i, local: ti.template(), shift, shifted: ti.template(), c, s):
        """``turned`` by the rotation (``c``, ``s``) = (cos, sin) of another angle."""
        out = ti.Matrix.zero(self.layout.real, self.maxv, 2)
        start, count = self.model.body_local_start[i], self.model.body_vert_count[i]
        for k in ti.static(range(self.maxv)):
            if k < count:
                v = local[start + k]
                if ti.static(shifted):
                    out[k, 0] = shift[0] + (c * v[0] - s * v[1])
                    out[k, 1] = shift[1] + (s * v[0] + c * v[1])
                else:
                    out[k, 0] = c * v[0] - s * v[1]
                    out[k, 1] = s * v[0] + c * v[1]
        return out

    @ti.func
    def add_force(self, i, force, torque, serial: ti.template()):
        """Add a contact's force and torque to body i (``state.gather``)."""
        gather(self.data.body_force_q, self.data.body_torque_q, i, force, torque, serial)

    @ti.func
    def add_shift(self, i, shift, torque, serial: ti.template()):
        """Add a contact's position impulse (as a force, 2 Q / dt^2) and its torque to body
        i (``state.gather``; the analytic step)."""
        gather(self.data.body_shift_q, self.data.body_turn_q, i, shift, torque, serial)

    @ti.func
    def relative(self, i, j, r_i, r_j, vel: ti.template(), omega: ti.template()):
        """``vel`` and ``omega`` (the bodies' velocities, or their last changes) of body j's
        point at r_j relative to body i's point at r_i."""
        return (vel[j] + perp(omega[j], r_j)) - (vel[i] + perp(omega[i], r_i))

    @ti.func
    def step_overlaps(
        self,
        i,
        j,
        p: ti.template(),
        p_normals: ti.template(),
        n_p,
        q: ti.template(),
        q_normals: ti.template(),
        n_q,
        separated,
        origin,
        h,
    ):
        """The overlap of owner i's outline ``p`` and partner j's ``q`` (relative to
        ``origin``, i's position; none if ``separated``): area, point, normal, width; and
        with the midstep step, if they overlap, the same at the pose predicted for mid-step
        (``midstep_outlines``) and where the centroids are then (zero otherwise)."""
        area = 0.0
        point, normal = ti.math.vec2(0.0, 0.0), ti.math.vec2(0.0, 0.0)
        width = 0.0
        a_m, w_m = 0.0, 0.0
        p_m, n_m = ti.math.vec2(0.0, 0.0), ti.math.vec2(0.0, 0.0)
        c_i = ti.Vector([0.0, 0.0], self.layout.real)
        c_j = ti.Vector([0.0, 0.0], self.layout.real)
        if ti.static(not self.layout.midstep or self.maxv <= SHARED_CLIP_VERTS):
            if not separated:
                area, point, normal, width, _ = overlap_normals_ti(
                    p, p_normals, n_p, q, q_normals, n_q
                )
            if ti.static(self.layout.midstep):
                if area > 0.0:
                    pm, pm_normals, qm, qm_normals, c_i, c_j = self.midstep_outlines(
                        i, j, origin, h
                    )
                    a_m, p_m, n_m, w_m, _ = overlap_normals_ti(
                        pm, pm_normals, n_p, qm, qm_normals, n_q
                    )
        else:
            # Both poses through one call of the clip, in a loop: inlined twice, the clip of
            # large outlines made the midstep kernels' compile 2.4x the coupled ones' (a
            # field of 16-gons: 71 s against 30 s from an empty cache on 2 cores; 41 s this
            # way). Not for 4-gons: their clip compiles fast, and this way the pillar's jam
            # stepped 6 % slower.
            pp, pp_normals, qq, qq_normals = p, p_normals, q, q_normals
            for k in range(0 if separated else 2):
                at_mid = k == 1
                if at_mid and area > 0.0:
                    pp, pp_normals, qq, qq_normals, c_i, c_j = self.midstep_outlines(
                        i, j, origin, h
                    )
                if not at_mid or area > 0.0:
                    a_k, p_k, n_k, w_k, _ = overlap_normals_ti(
                        pp, pp_normals, n_p, qq, qq_normals, n_q
                    )
                    if at_mid:
                        a_m, p_m, n_m, w_m = a_k, p_k, n_k, w_k
                    else:
                        area, point, normal, width = a_k, p_k, n_k, w_k
        return area, point, normal, width, a_m, p_m, n_m, w_m, c_i, c_j

    @ti.func
    def midstep_outlines(self, i, j, origin, h):
        """Bodies i and j at the configuration predicted for mid-step, each in free flight
        for h/2 (``midstep`` integrator): their outlines and edge normals, relative to
        ``origin`` (the owner's position at the step's start), and where their centroids
        are then; their overlap (``step_overlaps``) is the ``mid`` of
        ``reference_contact.contact_force``."""
        m, d = ti.static((self.model, self.data))
        zero = ti.Vector([0.0, 0.0], self.layout.real)
        c_i = ti.cast(d.body_pos[i] + 0.5 * h * d.body_vel[i] - origin, self.layout.real)
        c_j = ti.cast(d.body_pos[j] + 0.5 * h * d.body_vel[j] - origin, self.layout.real)
        rot_i = self.rotation(d.body_angle[i] + 0.5 * h * d.body_omega[i])
        rot_j = self.rotation(d.body_angle[j] + 0.5 * h * d.body_omega[j])
        p = self.turned_by(i, m.vert_local, c_i, True, rot_i[0], rot_i[1])
        p_normals = self.turned_by(i, m.vert_normal_local, zero, False, rot_i[0], rot_i[1])
        q = self.turned_by(j, m.vert_local, c_j, True, rot_j[0], rot_j[1])
        q_normals = self.turned_by(j, m.vert_normal_local, zero, False, rot_j[0], rot_j[1])
        return p, p_normals, q, q_normals, c_i, c_j

    @ti.func
    def rotation(self, angle):
        """(cos, sin) of ``angle`` as ``integrate.Integrator.turn`` computes a body's."""
        rot = ti.Vector([0.0, 0.0], self.layout.real)
        if ti.static(self.layout.precision == "f64"):
            rot = rotation_ti(angle)
        else:
            rot = ti.Vector([ti.cos(angle), ti.sin(angle)])
        return rot

    @ti.func
    def remember(self, i):
        """Body i's contact memory of the last step, copied out of its slots (which this
        step overwrites: only the owner's thread touches them, so one buffer suffices), and
        its count."""
        d, k = ti.static((self.data, self.layout.slots))
        # (Slot count, not the contact stiffness: one element when no budget is kept.)
        k_budget = ti.static(k if self.layout.energy else 1)
        old = ti.Struct(
            partner=ti.Vector.zero(ti.i32, k),
            xi=ti.Vector.zero(self.layout.real, k),
            elastic=ti.Vector.zero(self.layout.real, k_budget),
            theta=ti.Vector.zero(self.layout.real, k if self.layout.rate_state else 1),
            slip=ti.Vector.zero(self.layout.real, k if self.layout.rate_state else 1),
            crushed=ti.Vector.zero(self.layout.real, k if self.layout.crushing else 1),
            force=ti.Matrix.zero(self.layout.real, k if self.layout.analytic else 1, 2),
        )
        n_old = d.contact_count[i]
        for s in range(n_old):
            old.partner[s] = d.contact_partner[i, s]
            old.xi[s] = d.contact_xi[i, s]
            if ti.static(self.layout.energy):
                old.elastic[s] = d.contact_elastic[i, s]
            if ti.static(self.layout.rate_state):
                old.theta[s] = d.contact_theta[i, s]
                old.slip[s] = d.contact_slip[i, s]
            if ti.static(self.layout.crushing):
                old.crushed[s] = d.contact_crushed[i, s]
            if ti.static(self.layout.analytic):
                f = d.contact_force[i, s]
                old.force[s, 0] = f[0]
                old.force[s, 1] = f[1]
        return old, n_old

    @ti.func
    def settle(self, i):
        """Book again the work of body i's contacts of this step, at the velocity change the
        bodies took (``body_dvel``, ``body_domega``, the integrator's) instead of the one the
        contact stage estimated (``reference_contact.settle``). The analytic steps estimate
        a pair's change from its other forces of the last step and its own of this one,
        exact for a lone pair and off where every force of a jam grows together: the hard
        jam's budget was left open by 0.1 of the work done at 0.8 stable_dt (issue 30,
        docs/accuracy.md). Only the owner's thread touches its rows: plain stores."""
        d, slots = ti.static((self.data, self.layout.slots))
        dv_i, dw_i = d.body_dvel[i], d.body_domega[i]
        for s in range(ti.min(d.contact_count[i], slots)):
            b = d.contact_booking[i, s]
            j = d.contact_partner[i, s]
            dv, dw_j = d.body_dvel[j] - dv_i, d.body_domega[j]
            n = ti.Vector([b[6], b[7]])
            t = ti.Vector([-b[7], b[6]])
            d_n = -dv.dot(n) - dw_j * b[9] + dw_i * b[8] - b[0]
            d_t = dv.dot(t) + dw_j * b[11] - dw_i * b[10] - b[1]
            held, tangential = b[2] * d_n, b[4] * d_t
            friction = 0.0 * d_t
            if b[5] > 0.0:
                friction = tangential
            else:
                held += tangential
            d.contact_elastic[i, s] = d.contact_elastic[i, s] + held
            e_f = d.body_energy[i, BodyEnergy.FRICTION]
            d.body_energy[i, BodyEnergy.FRICTION] = e_f + friction
            e_v = d.body_energy[i, BodyEnergy.VISCOUS]
            d.body_energy[i, BodyEnergy.VISCOUS] = e_v + b[3] * d_n

    @ti.kernel
    def settle_all(self):
        """``settle`` every body in use, in parallel, after the integrator's stage."""
        for i in range(self.layout.n_bodies):
            if i < self.model.body_count[None]:
                self.settle(i)

    @ti.func
    def owns(self, i, j):
        """True if body i handles the pair (i, j) of two small bodies (see ``wants``)."""
        kind = ti.static(self.model.body_kind)
        dyn_i, dyn_j = kind[i] == BodyKind.DYNAMIC, kind[j] == BodyKind.DYNAMIC
        return (dyn_i and not dyn_j) or (dyn_i == dyn_j and dyn_i and i < j)

    @ti.func
    def near(self, i, j):
        """Bounding circles of bodies i and j overlap."""
        m, d = ti.static((self.model, self.data))
        reach = m.body_radius[i] + m.body_radius[j]
        return (d.body_pos[j] - d.body_pos[i]).norm_sqr() < reach * reach

    @ti.func
    def beyond_a_face(self, i, j, margin):
        """Body i's bounding circle, grown by ``margin``, lies wholly outside one face of
        body j (so they cannot overlap): a cheap rejection for large bodies, whose bounding
        circles (a wall's is half its length) meet nearly every small body of the world."""
        m, d = ti.static((self.model, self.data))
        q, n_q = self.outline(j, d.body_pos[i])  # relative to i's centroid
        r = m.body_radius[i] + margin
        outside = False
        for k in range(n_q):
            a = ti.Vector([q[k, 0], q[k, 1]])
            k1 = (k + 1) % n_q
            e = ti.Vector([q[k1, 0], q[k1, 1]]) - a
            # Outward normal of a counter-clockwise outline; i's centroid is the origin.
            if -a.dot(ti.Vector([e[1], -e[0]])) > r * e.norm():
                outside = True
        return outside

    @ti.func
    def wants(self, i, j):
        """True if body i handles the pair (i, j), j != i, of its world.

        Small dynamic bodies own their contacts with small bodies that are not dynamic and,
        among dynamic ones, those of higher id; small bodies own their contacts with large
        ones if either is dynamic (a small fixed or kinematic body, a pillar, those with
        large dynamic bodies); large bodies among themselves the lower id, if either moves.
        """
        m, _d = ti.static((self.model, self.data))
        dyn_i = m.body_kind[i] == BodyKind.DYNAMIC
        dyn_j = m.body_kind[j] == BodyKind.DYNAMIC
        keep = False
        if m.body_small[j]:
            keep = m.body_small[i] != 0 and self.owns(i, j)
        elif m.body_small[i]:
            keep = dyn_i or dyn_j
        else:
            keep = j > i and (dyn_i or dyn_j)
        return keep

    @ti.func
    def gap_bound(self, i, j, gap, path_i):
        """What ``nbr_gap`` keeps of a pair found ``gap`` apart (m; negative: not proven
        apart, -1 kept): the gap less a margin for round-off (``GAP_MARGIN`` of the two
        circumradii, far above the error of outlines turned and shifted in float32), plus
        both bodies' paths now, rounded down to float32. While the paths sum to less, no
        point of either body can have moved into the other."""
        m, nb = ti.static((self.model, self.neighbours))
        bound = ti.cast(-1.0, ti.f32)
        margin = GAP_MARGIN * ti.cast(m.body_radius[i] + m.body_radius[j], ti.f64)
        if gap > margin:
            total = gap - margin + path_i + nb.nbr_path[j]
            bound = ti.cast(total * (1.0 - 1e-6), ti.f32)  # f32 rounds to nearest: below
        return bound

    @ti.func
    def list_add(self, i, j, n):
        """Append j to body i's list (``n`` entries so far) if i owns the pair and their
        bounding circles come within the skin (for a large partner, also if i's circle does
        not lie wholly beyond one of its faces); returns the new count, which may pass the
        list's length (reported by ``end_list``)."""
        m, d, nb = ti.static((self.model, self.data, self.neighbours))
        skin = m.list_skin[None]
        # The circles first: they reject most pairs of a large world in one test that the
        # branch predictor learns, where ownership (``wants``) takes five loads and branches
        # it does not (the single-thread build tries every pair of the world).
        reach = m.body_radius[i] + m.body_radius[j] + skin
        if j != i and (d.body_pos[j] - d.body_pos[i]).norm_sqr() < reach * reach:
            if self.wants(i, j):
                if m.body_small[j] or not self.beyond_a_face(i, j, skin):
                    if n < self.layout.nbr_len:
                        nb.nbr_ids[i, n] = j
                    n += 1
        return n

    @ti.func
    def end_list(self, i, n):
        """Close body i's list of ``n`` entries: its count, where body i stands now, and the
        overflow report."""
        d, nb = ti.static((self.data, self.neighbours))
        nb.nbr_count[i] = ti.min(n, self.layout.nbr_len)
        nb.nbr_ref_pos[i] = d.body_pos[i]
        nb.nbr_ref_angle[i] = d.body_angle[i]
        # No entry proven apart yet; paths count from here (the world's lists are rebuilt
        # together, so a partner's path restarts too).
        nb.nbr_path[i] = 0.0
        for k in range(ti.min(n, self.layout.slots)):
            nb.nbr_gap[i, k] = ti.cast(-1.0, ti.f32)
        if n > self.layout.nbr_len:
            self.raise_status(self.model.body_world[i], Status.LIST_OVERFLOW, n)

    @ti.func
    def raise_status(self, w, code: ti.template(), value):
        """Raise world w's status word ``code`` to ``value``: atomically, or where integer
        atomics fail inside loops (``backend.float_gather``) by a plain store when it is
        higher, which another body of the world may overwrite with its own count above
        the limit (the overflow is still reported; the count may not be the largest)."""
        if ti.static(backend.float_gather()):
            if value > self.data.status[w, code]:
                self.data.status[w, code] = value
        else:
            ti.atomic_max(self.data.status[w, code], value)

    @ti.func
    def build_world(self, w):
        """Every list of world w by one thread (``WorldStepper``): the lists
        ``build_list_hashed`` builds. Trying every pair of the world took most of the step of
        a world of 1,000 fast bodies (a million pairs a rebuild); here its bodies are counted
        into strips across its longer side, each as wide as any small pair's reach (the
        spatial hash's cell), and a small body tries the small bodies
        of its strip and the two beside it, and the world's large bodies (``strip_ids``: the
        bodies strip by strip; ``strip_end``: where each strip's run ends)."""
        m, d, h = ti.static((self.model, self.data, self.hash))
        lo, hi = m.world_body_start[w], m.world_body_start[w + 1]
        low_x, low_y = ti.cast(1e300, ti.f64), ti.cast(1e300, ti.f64)
        high_x, high_y = -low_x, -low_y
        for k in range(lo, hi):
            if m.body_small[k]:
                p = d.body_pos[k]
                low_x, low_y = ti.min(low_x, p[0]), ti.min(low_y, p[1])
                high_x, high_y = ti.max(high_x, p[0]), ti.max(high_y, p[1])
        across = high_y - low_y > high_x - low_x  # the strips along y, else along x
        start = ti.select(across, low_y, low_x)
        span = ti.select(across, high_y, high_x) - start
        # The hash's cell: the batch's widest small diameter and the skin (widened by a
        # millionth: list_add's reach rounds in the run's precision).
        width = (1.0 + 1e-6) / m.grid_inv_cell[None]
        strips = 1
        if span > 0.0:  # some small bodies apart; at most a strip a body of the world
            strips = ti.cast(ti.min(span / width, hi - lo - 1.0), ti.i32) + 1
        if hi > lo:
            h.strip_end[lo] = 0
        for b in range(1, strips):
            h.strip_end[lo + b] = 0
        for k in range(lo, hi):
            if m.body_small[k]:
                b = self.strip(k, across, start, width, strips)
                # Plain loads and stores (one thread owns the world's rows): an augmented
                # assignment is an atomic, and integer atomics in loops fail on some GPUs.
                h.strip_end[lo + b] = h.strip_end[lo + b] + 1
        total = 0
        for b in range(strips):  # the counts become each strip's first entry
            count = h.strip_end[lo + b]
            h.strip_end[lo + b] = total
            total += count
        for k in range(lo, hi):  # ... and, filled, the entry after its last
            if m.body_small[k]:
                b = self.strip(k, across, start, width, strips)
                h.strip_ids[lo + h.strip_end[lo + b]] = k
                h.strip_end[lo + b] = h.strip_end[lo + b] + 1
        for i in range(lo, hi):
            n = 0
            if m.body_small[i]:
                b = self.strip(i, across, start, width, strips)
                first = 0
                if b >= 2:
                    first = h.strip_end[lo + b - 2]
                last = h.strip_end[lo + ti.min(b + 1, strips - 1)]
                for e in range(first, last):
                    n = self.list_add(i, h.strip_ids[lo + e], n)
            for g in range(m.world_large_start[w], m.world_large_start[w + 1]):
                n = self.list_add(i, m.large_ids[g], n)
            self.sort_list(i, n)
            self.end_list(i, n)

    @ti.func
    def strip(self, k, across, start, width, strips):
        """The strip of ``build_world`` that body k's centroid lies in."""
        p = self.data.body_pos[k]
        b = ti.cast((ti.select(across, p[1], p[0]) - start) / width, ti.i32)
        return ti.min(ti.max(b, 0), strips - 1)

    @ti.func
    def sort_list(self, i, n):
        """Body i's first ``n`` entries (at most the list's length) in ascending ids:
        an insertion sort of a few entries."""
        nb, _m = ti.static((self.neighbours, self.model))
        for k in range(1, ti.min(n, self.layout.nbr_len)):
            v = nb.nbr_ids[i, k]
            s = k
            while s > 0 and nb.nbr_ids[i, s - 1] > v:
                nb.nbr_ids[i, s] = nb.nbr_ids[i, s - 1]
                s -= 1
            nb.nbr_ids[i, s] = v

    @ti.func
    def build_list_hashed(self, i):
        """Body i's neighbour list from the 3 x 3 cells of the spatial hash around it and the
        large bodies of its world, sorted ascending: every body of its world it wants within
        reach (``list_add``), as ``build_world`` finds them."""
        m, d, h = ti.static((self.model, self.data, self.hash))
        w = m.body_world[i]
        n = 0
        if m.body_small[i]:
            c = h.cell_of(d.body_pos[i])
            for k in range(9):
                cell = c + ti.Vector([k % 3 - 1, k // 3 - 1])
                b = bucket_of(cell, w, h.mask)
                for e in range(h.bucket_end[b] - h.bucket_count[b], h.bucket_end[b]):
                    j = h.sorted_ids[e]
                    # A bucket may hold other cells or worlds: keep only this cell's bodies.
                    if m.body_world[j] == w:
                        cj = h.cell_of(d.body_pos[j])
                        if cj[0] == cell[0] and cj[1] == cell[1]:
                            n = self.list_add(i, j, n)
        for g in range(m.world_large_start[w], m.world_large_start[w + 1]):
            n = self.list_add(i, m.large_ids[g], n)
        self.sort_list(i, n)
        self.end_list(i, n)

    @ti.kernel
    def build_lists(self):
        """Rebuild the neighbour lists of every stale world from the spatial hash (built
        from the current positions first, ``SpatialHash.build``)."""
        m, nb = ti.static((self.model, self.neighbours))
        for i in range(self.layout.n_bodies):
            if i < m.body_count[None] and nb.world_nbr_stale[m.body_world[i]]:
                self.build_list_hashed(i)
        for w in range(self.layout.n_worlds):
            nb.world_nbr_stale[w] = 0
            if w == 0:
                nb.nbr_rebuild[None] = 0
