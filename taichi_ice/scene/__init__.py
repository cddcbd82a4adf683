"""What a scene is and how it is read: the model of floes, walls, pushers and probes, and
the parsing of scene files into it. NumPy only: importing this layer starts no Taichi.

``model`` holds the dataclasses (``Scene``, ``Body``, ...), ``parse`` reads TOML scene
files and tables into them (``load_scenario``), ``table`` is the typed reader of one TOML
table that every file format uses (it names the file, the key and the fix), ``overlaps``
finds bodies that overlap when a scene is read. ``voronoi`` tessellates a region into a
floe field (``[[field]] kind = "voronoi"``) with the geometry of ``tessellation``; ``floes``
reads floes from GeoJSON (``kind = "file"``) and shapely (``from_shapely``).

Layer 2 of the package (docs/architecture.md): imports physics and the base modules.
"""

from .model import Scene
from .parse import load_scenario, parse_scenario, reseeded, scene_from_dict

__all__ = ["Scene", "load_scenario", "parse_scenario", "reseeded", "scene_from_dict"]
