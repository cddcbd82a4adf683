"""Broad phase: neighbour lists with a skin, found through a spatial hash or all pairs.

A body's neighbour list (``NeighbourList``) holds the partners it owns whose bounding circles
come within the skin of its own; the contact stage filters it every step and it is rebuilt
only when a body of the world has moved half the skin. Two ways find the lists:

- stepping in parallel over bodies (large worlds), a spatial hash of the small bodies
  (``SpatialHash``), rebuilt with the lists: cells are squares of edge ``h`` = the diameter of
  the largest small body plus the skin, so two small bodies whose circles come within the
  skin are in neighbouring cells (3 x 3 search). A cell ``(cx, cy)`` of world ``w`` maps to
  one of H buckets (a power of two) by a multiplicative hash; buckets are counted,
  prefix-summed and filled, giving the ids of each bucket's bodies contiguous in
  ``sorted_ids`` (a counting sort). Two cells, or two worlds, that collide in one bucket are
  told apart by comparing the body's own cell and world, so a bucket collision costs a few
  wasted candidates, never a wrong or a duplicated pair;
- stepping a world in one thread (small worlds), all pairs of the world.

Large bodies (walls, pushers, anything bigger than the largest dynamic body) are not hashed:
every body checks the few large bodies of its world directly (state.large_ids).

The fields are declared in ``taichi_ice.engine.schema`` (``HASH``, ``NEIGHBOURS``).
"""

from __future__ import annotations

from typing import ClassVar

import taichi as ti

from . import schema
from .schema import SCAN, Layout
from .stages import Access, Stage
from .state import Data, Fields, Model

# SCAN (schema) is the block length of the two-level prefix sum: each block is summed
# serially by one thread and the H / SCAN block totals are scanned serially by one; both
# stay short on CPU and GPU.


@ti.func
def bucket_of(cell, world, mask):
    """Bucket of integer cell ``cell`` (ivec2) of ``world``; ``mask`` = H - 1."""
    # Large odd multipliers (Teschner et al. 2003) spread neighbouring cells across buckets.
    h = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (world * 83492791)
    return h & mask


@ti.data_oriented
class SpatialHash(Fields, Stage):
    """Counting-sort spatial hash over the small bodies of every world."""

    ACCESS: ClassVar[dict[str, Access]] = {
        "build": Access(
            reads=(
                "body_count",
                "body_small",
                "body_world",
                "body_pos",
                "grid_inv_cell",
                "bucket_count",
                "bucket_end",
                "block_total",
            ),
            writes=("bucket_count", "bucket_end", "block_total", "sorted_ids"),
        )
    }

    def __init__(self, layout: Layout, model: Model, data: Data):
        super().__init__(layout, schema.groups()["hash"])
        self.model, self.data = model, data
        h = layout.hash_size
        self.mask = h - 1
        self.n_blocks = layout.size("scan_blocks")

    @ti.func
    def cell_of(self, pos):
        """The hash cell of a position: cells are a body's diameter plus the skin, so bodies
        whose circles come within the skin are at most a cell apart."""
        inv_cell = self.model.grid_inv_cell[None]
        return ti.Vector([ti.floor(pos[0] * inv_cell, ti.i32), ti.floor(pos[1] * inv_cell, ti.i32)])

    @ti.kernel
    def build(self):
        """Count, scan and fill the buckets from the current body positions.

        The scan writes each bucket's start to ``bucket_end`` and the fill advances it, so
        a bucket's entries end up at ``[bucket_end - bucket_count, bucket_end)``: no cursor
        field, no stored cell (``cell_of`` the position again is cheaper than 8 B a body)."""
        m, d = ti.static((self.model, self.data))
        for b in self.bucket_count:
            self.bucket_count[b] = 0
        for i in range(self.layout.n_bodies):
            if i < m.body_count[None] and m.body_small[i]:
                b = bucket_of(self.cell_of(d.body_pos[i]), m.body_world[i], self.mask)
                ti.atomic_add(self.bucket_count[b], 1)
        # Two-level exclusive scan: block-local sums in parallel, block offsets serially.
        for blk in range(self.n_blocks):
            running = 0
            for k in range(blk * SCAN, ti.min((blk + 1) * SCAN, self.mask + 1)):
                self.bucket_end[k] = running
                running += self.bucket_count[k]
            self.block_total[blk] = running
        ti.loop_config(serialize=True)
        for blk in range(self.n_blocks):
            if blk > 0:
                self.block_total[blk] += self.block_total[blk - 1]
        for k in range(self.mask + 1):
            blk = k // SCAN
            if blk > 0:
                self.bucket_end[k] += self.block_total[blk - 1]
        for i in range(self.layout.n_bodies):
            if i < m.body_count[None] and m.body_small[i]:
                b = bucket_of(self.cell_of(d.body_pos[i]), m.body_world[i], self.mask)
                self.sorted_ids[ti.atomic_add(self.bucket_end[b], 1)] = i


class NeighbourList(Fields):
    """Each body's candidate partners, found with a margin (the skin) and reused for many
    steps (a Verlet list).

    A body's list holds the partners of its world it owns whose bounding circles come within
    the skin (``list_skin``) of its own, in ascending id (``ContactLists.build_world``, a
    thread per world, or ``build_lists`` through the hash). As long as no body of the world
    has moved more than half the skin since (``Integrator.moved``), no
    pair outside the lists can have come into contact, so each step only filters its list by
    the exact bounding-circle test; the step that finds a body past half the skin marks the
    world's lists stale (``world_nbr_stale``, and ``nbr_rebuild`` for the parallel step), and
    they are rebuilt before its next step. The lists are scratch: a world without valid lists
    (1 at the start) rebuilds them first.

    Between rebuilds most listed pairs are not even tested: a pair that the contact stage
    found apart by a gap (a facing edge, or the bounding circles) cannot touch until the two
    bodies have together moved that far, and each body adds up how far any of its points can
    have moved since its list was built (``nbr_path``: centroid step plus circumradius times
    turn, ``Integrator.displace``). The gap is kept with both paths added
    (``nbr_gap``, ``ContactStage.gap_bound``), so one comparison a step settles the pair; it
    skips only pairs the test would find apart, and the state is the same bit for bit.

    Its fields are declared in ``taichi_ice.engine.schema`` (``NEIGHBOURS``).
    """

    def __init__(self, layout: Layout):
        super().__init__(layout, schema.groups()["nbr"])
