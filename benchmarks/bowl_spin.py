"""The bowl's disk on a slip wall: its spin against its orbit's angular rate about the bowl's
centre (docs/boundaries.md, "The slip wall's drag").

    .venv/bin/python benchmarks/bowl_spin.py CELLS
"""
import sys

import numpy as np

import fempm  # noqa: F401  (before dolfinx)
from fempm.scenes.bowl import bowl
from fempm.scene.loop import run
cells = int(sys.argv[1])
sc = bowl(cells=cells, frames=0, periods=1.0)
s = run(sc, progress=False)
t, cx, cy, vx, vy, om = np.array(sc.watch.points).T
rx, ry = cx - 0.0, cy - 1.0
Om = (rx * vy - ry * vx) / (rx**2 + ry**2)  # the orbit's angular rate about the bowl's centre
k = np.abs(Om) > 0.3 * np.abs(Om).max()
print(cells, "omega/Omega median", np.median(om[k] / Om[k]), "spin", s["spin"], "period_error", s["period_error"])
