"""The current and the wind at a floe's centroid: the gather that the integrator's step calls.

A scene's current (``[water] current``) and wind (``[wind] velocity``) are uniform, one value
per world (``world_current``, ``world_wind``), or given on a grid that every world of the
batch shares (``grid_values``, row 0 of ``grid_origin``, ``grid_spacing`` and ``grid_size``
for the current, row 1 for the wind). A grid is sampled at the body's centroid, at the time
of the step's start (``body_time``, kept only where a grid has a t axis): bilinear in x and
y, linear in t, constant beyond the grid (``physics.forcing.grid_sample`` is the NumPy twin,
in the same order). The forcing is taken at the centroid for the whole floe: a floe much
smaller than the grid's cells, which is what a DEM of rubble in an ocean model's field is.

Nothing here is compiled into a step whose layout has no current and no wind
(``Layout.current``, ``Layout.wind``): the integrator calls it under ``ti.static``.
"""

# No "from __future__ import annotations": Taichi reads kernel annotations as objects.

from typing import ClassVar

import taichi as ti

from ..physics.forcing_ti import grid_cell_ti, lerp_ti
from .schema import Layout
from .stages import Access, Stage
from .state import Data, Model

# Rows of the grid tables (``grid_origin``, ``grid_spacing``, ``grid_size``).
CURRENT, WIND = 0, 1


@ti.data_oriented
class Forcing(Stage):
    """Functions of the integrator's step (no kernel of its own)."""

    ACCESS: ClassVar[dict[str, Access]] = {}

    def __init__(self, layout: Layout, model: Model, data: Data):
        self.layout, self.model, self.data = layout, model, data

    @ti.func
    def current(self, i):
        """The ocean current at body i (m/s); zero without one."""
        m, _d = ti.static((self.model, self.data))
        u = ti.Vector([0.0, 0.0], self.layout.real)
        if ti.static(self.layout.current_grid):
            u = self.sample(CURRENT, i)
        elif ti.static(self.layout.current):
            u = m.world_current[m.body_world[i]]
        return u

    @ti.func
    def wind(self, i):
        """The wind at body i (m/s); zero without one."""
        m, _d = ti.static((self.model, self.data))
        u = ti.Vector([0.0, 0.0], self.layout.real)
        if ti.static(self.layout.wind_grid):
            u = self.sample(WIND, i)
        elif ti.static(self.layout.wind):
            u = m.world_wind[m.body_world[i]]
        return u

    @ti.func
    def sample(self, g, i):
        """Grid ``g`` (``CURRENT`` or ``WIND``) at body i's centroid and clock."""
        m, d = ti.static((self.model, self.data))
        pos = d.body_pos[i]
        t = ti.cast(0.0, ti.f64)
        if ti.static(self.layout.clock):
            t = d.body_time[i]
        nx, ny, nt = m.grid_size[g, 0], m.grid_size[g, 1], m.grid_size[g, 2]
        x0, x1, wx = grid_cell_ti((pos[0] - m.grid_origin[g, 0]) / m.grid_spacing[g, 0], nx)
        y0, y1, wy = grid_cell_ti((pos[1] - m.grid_origin[g, 1]) / m.grid_spacing[g, 1], ny)
        t0, t1, wt = grid_cell_ti((t - m.grid_origin[g, 2]) / m.grid_spacing[g, 2], nt)
        ax = ti.cast(wx, self.layout.real)
        ay = ti.cast(wy, self.layout.real)
        u = self.plane(g, t0, x0, x1, ax, y0, y1, ay)
        if ti.static(self.layout.clock):
            u1 = self.plane(g, t1, x0, x1, ax, y0, y1, ay)
            u = lerp_ti(u, u1, ti.cast(wt, self.layout.real))
        return u

    @ti.func
    def plane(self, g, k, x0, x1, wx, y0, y1, wy):
        """Grid ``g`` at its time node k, bilinear between the nodes (x0, x1) x (y0, y1)."""
        m, v = ti.static((self.model, self.model.grid_values))
        nx, ny = m.grid_size[g, 0], m.grid_size[g, 1]
        base = m.grid_size[g, 3] + k * ny * nx
        lo = lerp_ti(v[base + y0 * nx + x0], v[base + y0 * nx + x1], wx)
        hi = lerp_ti(v[base + y1 * nx + x0], v[base + y1 * nx + x1], wx)
        return lerp_ti(lo, hi, wy)
