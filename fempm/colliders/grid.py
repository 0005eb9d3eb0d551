r"""Rigid colliders on the grid: non-penetration and Coulomb friction at the nodes a collider
touches, and the reaction it takes.

A collider :math:`k` (:class:`fempm.colliders.Collider`) is a shape of signed distance
:math:`\phi_k` translated by :math:`s_k(t) = \int_0^t u_k\, dt` with its velocity
:math:`u_k(t)`. A node :math:`i` touches it when the body's centre of mass as the node sees it,
:math:`\bar x_i = \sum_p M_p N_{ip} x_p / m_i` (:class:`fempm.transfer.centres.NodalCentres`),
lies within the gap :math:`g_i` of its surface, the position check of Nairn, Bardenhagen and
Smith (2018) that the grid walls with a gap use (:class:`fempm.boundary.walls.Friction`):

.. math::
    \delta_i = g_i - \phi_k(\bar x_i - s_k) > 0, \qquad
    \hat n_i = -\nabla\phi_k(\bar x_i - s_k)

(depth :math:`\delta_i`, normal :math:`\hat n_i` into the collider). On the updated grid
velocity of a step (it acts on the update only, as the absorbing dashpots do:
:meth:`fempm.boundary.conditions.GridConditions.apply`), the velocity relative to the collider
:math:`w_i = v_i - u_k(t + \Delta t/2)` of the touching nodes that approach it,
:math:`w_{n,i} = w_i \cdot \hat n_i > 0`, gives up the normal momentum
:math:`P = \sum m_j w_{n,j}` of its patch of touching nodes
(:class:`fempm.boundary.patches.Patches`), shared by depth as at a rigid body in contact
(:func:`fempm.stepping.contact.correct`), and at most :math:`\mu` times that of its tangential
part (:func:`fempm.boundary.coulomb.coulomb`):

.. math::
    \Delta w_{n,i} = P \frac{\delta_i}{\sum_j m_j \delta_j}, \qquad
    v_i^+ = u_k + w_{t,i} \max\Big(0, 1 - \mu\frac{\Delta w_{n,i}}{|w_{t,i}|}\Big)
    + (w_{n,i} - \Delta w_{n,i})\, \hat n_i .

A separating node is free. A touching node that lies inside the shape itself,
:math:`\phi_k(x_i - s_k) < 0`, gives up all of its approach, :math:`\Delta w_{n,i} = w_{n,i}`,
and shares none: where the surface cuts the grid at an angle such nodes see only a sliver of
the body, and a share by depth would throw that sliver off the collider (the rolling disk
gained 8 % energy and hopped, docs/colliders.md). The collider takes the momentum the body gives up,

.. math::
    J_k = \sum_i m_i (v_i - v_i^+)

over the owned dofs of every rank (the impulse of a step; its force :math:`J_k/\Delta t`), which
is exactly the body's loss: the particles' momentum changes by
:math:`\sum_p M_p \sum_i N_{ip} \Delta v_i = \sum_i m_i \Delta v_i` under FLIP and PIC with the
lumped masses :math:`m_i`. The work the collider does on the body is :math:`-J_k \cdot u_k`;
a run's energy check counts it (:class:`fempm.stepping.health.HealthMonitor`).

The collider's motion over a step is integrated from its velocity,
:math:`\Delta s_k = \int_t^{t + \Delta t} u_k\, dt` (Gauss-Legendre, 5 points: exact for a
velocity polynomial of degree 9 in time, such as a smoothstep ramp), and :math:`u_k` above is
its mean :math:`\Delta s_k / \Delta t`. The step honours the colliders as it honours the
waves (:meth:`ColliderContact.max_step`): no collider moves more than the CFL number times the
smallest cell of the mesh in a step, so that it meets every layer of nodes on its way and a
body cannot be passed through; the speed is sampled over the step, so that a short fast
stroke is seen.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import dolfinx.fem
import dolfinx.la
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.boundary.coulomb import coulomb
from fempm.boundary.patches import Patches, depth_shares
from fempm.colliders.collider import Collider
from fempm.transfer.centres import NodalCentres

__all__ = ["ColliderContact"]

_AXES = "xyz"
#: a node deeper than this fraction of its gap inside a collider's shape is held node by node
INSIDE = 1e-6
#: the fractions of a step at which :meth:`ColliderContact.max_step` samples the speeds
SAMPLES = np.linspace(0.0, 1.0, 17)
#: the 5-point Gauss-Legendre rule on [-1, 1] (the mean velocity over a step)
GAUSS = np.polynomial.legendre.leggauss(5)


class ColliderContact:
    """The ``colliders`` on the velocity space ``V`` (the module): a grid condition that acts on
    the update (:attr:`acts_on_update`), and the colliders' positions and reactions over the run.

    Args:
        V: The velocity space.
        colliders: The colliders (:class:`fempm.colliders.Collider`).
        h_cell: The cell sizes of ``V``'s mesh (:func:`fempm.meshes.cell_sizes.cell_sizes`),
            for the default gaps.
        t: The start time (where the colliders are at their given positions).

    Raises:
        TypeError: A collider that is not a :class:`fempm.colliders.Collider`.
        ValueError: A collider of another dimension than the mesh's.

    Note:
        Construction and :meth:`on_update` are collective.
    """

    needs_positions: ClassVar[bool] = True
    zero_components: ClassVar[bool] = False
    kind: ClassVar[str] = "colliders"
    acts_on_update: ClassVar[bool] = True

    def __init__(self, V: dolfinx.fem.FunctionSpace, colliders: Sequence[Collider], h_cell: npt.NDArray,
                 t: float = 0.0):
        self.colliders = tuple(colliders)
        d = V.mesh.geometry.dim
        for k, c in enumerate(self.colliders):
            if not isinstance(c, Collider):
                raise TypeError(f"colliders[{k}] is a {type(c).__name__}; expected a fempm.colliders.Collider")
            if c.dim != d:
                raise ValueError(f"colliders[{k}] has a shape of dimension {c.dim}; the mesh has {d}")
        self.comm = V.mesh.comm
        self.d = d
        self.num_owned = V.dofmap.index_map.size_local
        self.patches = Patches.of_space(V) if self.colliders else None
        self.points = V.tabulate_dof_coordinates()[:, :d] if self.colliders else None
        nodal = _nodal_gaps(V, h_cell) if any(c.gap is None for c in self.colliders) else None
        self.gaps = [nodal if c.gap is None else np.full(len(self.points), c.gap) for c in self.colliders]
        n = len(self.colliders)
        self.t = t
        local = float(np.min(h_cell, initial=np.inf))
        self.h_min = self.comm.allreduce(local, op=MPI.MIN) if self.colliders else np.inf
        self._mean = np.zeros((n, d))  # this step's mean velocities
        self.displacement = np.zeros((n, d))
        self.impulse = np.zeros((n, d))  # over the run
        self.force = np.zeros((n, d))  # of the last step
        self.work = np.zeros(n)  # done on the bodies over the run
        self._step = np.zeros((n, d))  # this step's impulse
        #: this step's impulse of all colliders at each owned dof (owned + ghost dofs, d; ghosts 0)
        self.nodal_impulse = np.zeros((len(self.points), d)) if self.colliders else np.zeros((0, d))

    def __len__(self) -> int:
        return len(self.colliders)

    # -- the step ------------------------------------------------------------------------------
    def max_step(self, t: float, dt: float, cfl: float) -> float:
        """The largest step from ``t``, at most ``dt``, in which no collider moves faster than
        ``cfl`` times the smallest cell size per step: the speed is sampled at 17 times over the
        step and the step shortened until it holds over the shorter step too (``dt`` itself
        without colliders or where they are slow enough)."""
        if not self.colliders or not np.isfinite(self.h_min):
            return dt
        reach = cfl * self.h_min
        for _ in range(40):
            speed = max(float(np.linalg.norm(c.velocity_at(t + f * dt))) for c in self.colliders for f in SAMPLES)
            if speed * dt <= reach * (1.0 + 1e-12):
                return dt
            dt = reach / speed
        return dt

    def begin(self, t: float, dt: float) -> None:
        """A step from time ``t`` of size ``dt`` starts: each collider's mean velocity over it."""
        self.t = t
        self._step[:] = 0.0
        self.nodal_impulse.fill(0.0)
        for k, c in enumerate(self.colliders):
            self._mean[k] = 0.5 * sum(w * c.velocity_at(t + 0.5 * dt * (1.0 + x)) for x, w in zip(*GAUSS))

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        """The mapped velocity is free: the colliders act on the update (:meth:`on_update`)."""

    def on_update(self, v: npt.NDArray, centroids: NodalCentres, dt: float) -> None:
        """Every collider on the updated grid velocity ``v`` (dofs, d) of a step ``dt``, in place
        (the module); adds the impulses it takes to the step's. Collective."""
        for k, c in enumerate(self.colliders):
            self._step[k] += self._collide(k, c, v, centroids, self._mean[k])

    def _collide(self, k: int, c: Collider, v: npt.NDArray, centroids: NodalCentres, u: npt.NDArray) -> npt.NDArray:
        """Collider ``k`` moving at ``u`` on ``v``; returns the impulse it took (summed over ranks)."""
        s = self.displacement[k]
        cand = np.flatnonzero(centroids.mass > 0.0)
        x = centroids.centre[cand] - s
        depth = self.gaps[k][cand] - c.shape.distance(x)
        touch = depth > 0.0
        dofs, depth = cand[touch], depth[touch]
        n = -c.shape.normal_at(x[touch])
        m = centroids.mass[dofs]
        w = v[dofs] - u
        wn = np.einsum("kd,kd->k", w, n)
        held = wn > 0.0
        inside = c.shape.distance(self.points[dofs] - s) < -INSIDE * self.gaps[k][dofs]  # node by node
        shares = held & ~inside
        dwn = depth_shares(self.patches.sums, dofs, m, np.where(shares, wn, 0.0), np.where(shares, depth, 0.0))
        dwn = np.where(inside, wn, dwn)
        new = np.where(held[:, None], u + coulomb(w - wn[:, None] * n, wn, n, dwn, c.friction), v[dofs])
        owned = dofs < self.num_owned
        nodal = m[owned, None] * (v[dofs[owned]] - new[owned])
        self.nodal_impulse[dofs[owned]] += nodal
        taken = nodal.sum(axis=0)
        v[dofs] = new
        return self.comm.allreduce(np.asarray(taken, dtype=np.float64), op=MPI.SUM)

    def end(self, dt: float) -> None:
        """The step of size ``dt`` that began at :meth:`begin` has ended: the colliders move and
        their reactions are recorded."""
        for k in range(len(self.colliders)):
            u = self._mean[k]
            self.displacement[k] += dt * u
            self.impulse[k] += self._step[k]
            self.force[k] = self._step[k] / dt
            self.work[k] -= self._step[k] @ u
        self.t += dt

    # -- the record ----------------------------------------------------------------------------
    @property
    def total_impulse(self) -> npt.NDArray:
        """(d,): the impulse all colliders took over the run (the bodies lost it)."""
        return self.impulse.sum(axis=0)

    @property
    def total_work(self) -> float:
        """The work all colliders did on the bodies over the run."""
        return float(self.work.sum())

    def columns(self) -> dict[str, float]:
        """The ``energies.csv`` columns: per collider k its force (of the last step), impulse and
        displacement (over the run), ``collider_force_<k>_x`` etc."""
        out = {}
        for what, values in (("force", self.force), ("impulse", self.impulse), ("displacement", self.displacement)):
            for k, row in enumerate(values):
                out.update({f"collider_{what}_{k}_{_AXES[a]}": float(row[a]) for a in range(self.d)})
        return out

    def summary(self) -> dict:
        """The ``summary.json`` entry ``colliders`` (none without colliders)."""
        if not self.colliders:
            return {}
        return {"colliders": [{"force": f.tolist(), "impulse": i.tolist(), "displacement": s.tolist(), "work": float(w)}
                              for f, i, s, w in zip(self.force, self.impulse, self.displacement, self.work)]}

    def state_dict(self) -> dict:
        """What a continued run needs (:meth:`load_state_dict`; JSON values)."""
        return {"displacement": self.displacement.tolist(), "impulse": self.impulse.tolist(),
                "force": self.force.tolist(), "work": self.work.tolist()}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict`.

        Raises:
            ValueError: A state of another number of colliders or dimension.
        """
        shape = self.displacement.shape
        arrays = {k: np.asarray(state[k], dtype=np.float64) for k in ("displacement", "impulse", "force", "work")}
        if arrays["displacement"].reshape(-1, self.d).shape != shape or len(arrays["work"]) != len(self):
            raise ValueError(f"the checkpoint holds the state of {len(arrays['work'])} collider(s); this run has "
                             f"{len(self)}")
        for k in ("displacement", "impulse", "force"):
            setattr(self, k, arrays[k].reshape(shape))
        self.work = arrays["work"]


def _nodal_gaps(V: dolfinx.fem.FunctionSpace, h_cell: npt.NDArray) -> npt.NDArray:
    """Half the smallest size of the cells around each dof over the degree (owned + ghost dofs;
    the owner's value, the same on every rank)."""
    index_map = V.dofmap.index_map
    cells = np.asarray(V.dofmap.list)  # every local cell, as h_cell
    h = np.full(index_map.size_local + index_map.num_ghosts, np.inf)
    np.minimum.at(h, cells.ravel(), np.repeat(h_cell, cells.shape[1]))
    vec = dolfinx.la.vector(index_map)
    vec.array[:] = h
    vec.scatter_forward()  # the owner's value on its ghosts
    return 0.5 * vec.array.copy() / V.element.basix_element.degree
