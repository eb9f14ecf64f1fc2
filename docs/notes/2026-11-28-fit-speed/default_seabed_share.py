"""The default scene's own seabed: its std and share of nodes within 5 cm of flat.

The nodes of the rendered seabed (with sand's micro-relief) under the track's pings, between
0.5 m and 40 m from it across track. Run: ``python
docs/notes/2026-11-28-fit-speed/default_seabed_share.py`` (a few seconds).
"""

import numpy as np

import sonar_raster as sr

setup = sr.load_scene("default")
track = setup.trajectory.positions
v = setup.scene.vertices
seabed = v[setup.scene.faces[setup.scene.object_id == 0].ravel()]
seabed = np.unique(seabed, axis=0)
keep = (
    (abs(seabed[:, 0]) > 0.5)
    & (abs(seabed[:, 0]) < 40.0)
    & (seabed[:, 1] >= track[:, 1].min())
    & (seabed[:, 1] <= track[:, 1].max())
)
z = seabed[keep, 2]
print(
    f"{keep.sum()} nodes: mean {100 * z.mean():+.2f} cm, std {100 * z.std():.2f} cm, "
    f"within 5 cm of flat {100 * np.mean(abs(z) < 0.05):.1f} %"
)
