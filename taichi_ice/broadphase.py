"""Broad phase: a spatial hash of the small bodies, rebuilt every step.

Cells are squares of edge ``h`` = the diameter of the largest small body, so two small bodies
can only touch if their cells are neighbours (3 x 3 search). A cell ``(cx, cy)`` of world
``w`` maps to one of H buckets (a power of two) by a multiplicative hash; buckets are
counted, prefix-summed and filled, giving the ids of each bucket's bodies contiguous in
``sorted_ids`` (a counting sort). Two cells, or two worlds, that collide in one bucket are
told apart by comparing the body's own cell and world, so a bucket collision costs a few
wasted candidates, never a wrong or a duplicated pair.

Large bodies (walls, pushers, anything bigger than ``h``) are not hashed: every body checks
the few large bodies of its world directly (state.large_ids).

Fields

=============== ===== ============= ==============================================
bucket_count    i32   H             bodies in each bucket this step
bucket_start    i32   H             first entry of each bucket in sorted_ids
bucket_fill     i32   H             scatter cursor while filling
block_total     i32   H / SCAN      per-block totals of the two-level scan
sorted_ids      i32   S             small body ids, grouped by bucket
body_cell       ivec2 N             integer cell of each small body
=============== ===== ============= ==============================================
"""

from __future__ import annotations

import numpy as np
import taichi as ti

from .state import Data, Layout, Model

# Block length of the two-level prefix sum: each block is summed serially by one thread and
# the H / SCAN block totals are scanned serially by one; both stay short on CPU and GPU.
SCAN = 256


def hash_size_for(n_small: int) -> int:
    """Smallest power of two >= 2 n_small (at least SCAN): load factor below one half."""
    return max(SCAN, 1 << int(np.ceil(np.log2(max(2 * n_small, 2)))))


@ti.func
def bucket_of(cell, world, mask):
    """Bucket of integer cell ``cell`` (ivec2) of ``world``; ``mask`` = H - 1."""
    # Large odd multipliers (Teschner et al. 2003) spread neighbouring cells across buckets.
    h = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (world * 83492791)
    return h & mask


@ti.data_oriented
class SpatialHash:
    """Counting-sort spatial hash over the small bodies of every world."""

    def __init__(self, layout: Layout, model: Model, data: Data):
        self.layout, self.model, self.data = layout, model, data
        h = layout.hash_size
        self.inv_cell = 1.0 / layout.cell_size
        self.mask = h - 1
        self.n_blocks = (h + SCAN - 1) // SCAN
        self.bucket_count = ti.field(ti.i32, shape=h)
        self.bucket_start = ti.field(ti.i32, shape=h)
        self.bucket_fill = ti.field(ti.i32, shape=h)
        self.block_total = ti.field(ti.i32, shape=self.n_blocks)
        self.sorted_ids = ti.field(ti.i32, shape=max(layout.n_small, 1))
        self.body_cell = ti.Vector.field(2, ti.i32, shape=max(layout.n_bodies, 1))

    @ti.func
    def cell_of(self, pos):
        return ti.Vector(
            [ti.floor(pos[0] * self.inv_cell, ti.i32), ti.floor(pos[1] * self.inv_cell, ti.i32)]
        )

    @ti.kernel
    def build(self):
        """Count, scan and fill the buckets from the current body positions."""
        m, d = ti.static((self.model, self.data))
        for b in self.bucket_count:
            self.bucket_count[b] = 0
            self.bucket_fill[b] = 0
        for i in range(self.layout.n_bodies):
            if m.body_small[i]:
                c = self.cell_of(d.body_pos[i])
                self.body_cell[i] = c
                ti.atomic_add(self.bucket_count[bucket_of(c, m.body_world[i], self.mask)], 1)
        # Two-level exclusive scan: block-local sums in parallel, block offsets serially.
        for blk in range(self.n_blocks):
            running = 0
            for k in range(blk * SCAN, ti.min((blk + 1) * SCAN, self.mask + 1)):
                self.bucket_start[k] = running
                running += self.bucket_count[k]
            self.block_total[blk] = running
        ti.loop_config(serialize=True)
        for blk in range(self.n_blocks):
            if blk > 0:
                self.block_total[blk] += self.block_total[blk - 1]
        for k in range(self.mask + 1):
            blk = k // SCAN
            if blk > 0:
                self.bucket_start[k] += self.block_total[blk - 1]
        for i in range(self.layout.n_bodies):
            if m.body_small[i]:
                b = bucket_of(self.body_cell[i], m.body_world[i], self.mask)
                self.sorted_ids[self.bucket_start[b] + ti.atomic_add(self.bucket_fill[b], 1)] = i
