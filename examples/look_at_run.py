"""Look at a run file with xarray: what it holds, a few numbers, and a figure of its series.

    python examples/look_at_run.py runs/my_scene.h5              # writes runs/my_scene_look.png

A run file is netCDF-4: ``open_run`` merges its groups (series on ``time``, frames on
``frame_time``, bodies on ``body``) into one ``xarray.Dataset`` whose attributes are the
run's provenance; ``xr.open_dataset(path, group="series")`` opens one group alone.
"""

from __future__ import annotations

import sys
from pathlib import Path

from matplotlib.figure import Figure

from taichi_ice import open_run

if len(sys.argv) != 2:
    sys.exit(__doc__)
path = Path(sys.argv[1])
ds = open_run(path)
print(f"{ds.attrs['title']}: status {ds.attrs['status']}, {ds.attrs['friction']}")
print(f"{ds.sizes['body']} bodies, {ds.sizes['time']} samples, {ds.sizes['frame_time']} frames")

force = (ds.probe_force**2).sum("xy") ** 0.5  # N, on each probe body, against time
for probe in ds.probe.values:
    name = str(ds.names.sel(body=probe).values)
    peak = force.sel(probe=probe)
    print(f"peak force on {name}: {float(peak.max()) / 1e3:.4g} kN at {float(peak.idxmax()):.2f} s")
print(
    f"frictional energy: {float(ds.friction_energy[-1]):.4g} J of {float(ds.work_in[-1]):.4g} J in"
)

fig = Figure(figsize=(8, 3.2), layout="constrained")  # no pyplot needed: a bare Figure
ax_force, ax_energy = fig.subplots(1, 2)
for probe in ds.probe.values:
    label = str(ds.names.sel(body=probe).values)
    ax_force.plot(ds.time, force.sel(probe=probe) / 1e3, label=label)
ax_force.set_xlabel("time (s)")
ax_force.set_ylabel("force on the probe (kN)")
ax_force.legend(fontsize=8)
terms = ("work_in", "kinetic_energy", "elastic_energy", "friction_energy", "viscous_energy")
for name in (*terms, "drag_energy", "crushing_energy"):
    if not ds[name].any():
        continue  # a term this run never booked (no water, no ice strength ...)
    ax_energy.plot(ds.time, ds[name], label=name.replace("_", " "))
ax_energy.set_xlabel("time (s)")
ax_energy.set_ylabel("energy (J)")
ax_energy.legend(fontsize=8)
figure = path.with_name(f"{path.stem}_look.png")
fig.savefig(figure, dpi=80)
print(f"wrote {figure}")
