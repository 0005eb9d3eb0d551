r"""Grid boundary conditions on the velocity dofs of a blocked (vector) space.

* :class:`Fixed`: :math:`v_i = 0` on the dofs.
* :class:`Slip`: no flow through a wall of unit normal :math:`n` (any direction):
  :math:`v_i \leftarrow v_i - (v_i \cdot n)\, n`.
* :class:`Prescribed`: velocity components held at given values (a moving rigid plate).
* :class:`Friction`: a rigid wall with Coulomb friction; with a ``gap`` it holds only the nodes
  a body touches and shares the normal momentum it takes over each patch of them by depth
  (:class:`fempm.boundary.patches.Patches`, :class:`NodalCentres`).

Dofs are located with DOLFINx (``locate_dofs_geometrical`` or, from gmsh facet tags,
``locate_dofs_topological``); they are block indices of the vector space.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import numpy.typing as npt

from fempm.boundary.coulomb import coulomb
from fempm.boundary.patches import Patches, depth_shares
from fempm.transfer.centres import NodalCentres

__all__ = [
    "Fixed", "Friction", "Prescribed", "Slip", "fixed", "fixed_on_facets", "friction", "friction_wall",
    "locate_dofs", "prescribed", "slip",
]


@dataclass(frozen=True)
class Fixed:
    """Every velocity component 0 at ``dofs``."""

    dofs: npt.NDArray[np.int32]
    #: whether the condition needs the step's nodal centres of mass (:class:`NodalCentres`)
    needs_positions: ClassVar[bool] = False
    #: what the condition is, in messages
    kind: ClassVar[str] = "fixed dofs"

    @property
    def zero_components(self) -> bool:
        """Whether the condition only holds velocity components at 0 (the compiled grid update
        then fuses it into its pass)."""
        return True

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        v[self.dofs] = 0.0


@dataclass(frozen=True)
class Slip:
    """No flow through a wall of unit ``normal`` at ``dofs``."""

    dofs: npt.NDArray[np.int32]
    normal: npt.NDArray  # (d,) or (len(dofs), d), unit
    needs_positions: ClassVar[bool] = False

    @property
    def kind(self) -> str:
        return "a slip wall" + ("" if self.axis is not None else " whose normal is not a coordinate axis")

    @property
    def axis(self) -> int | None:
        """The coordinate axis of a wall normal to it (then :meth:`apply` zeroes that component), else None."""
        return _axis(self.normal)

    @property
    def zero_components(self) -> bool:
        return self.axis is not None

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        axis = self.axis
        if axis is not None:  # a wall normal to a coordinate axis: that component is 0
            v[self.dofs, axis] = 0.0
            return
        n = np.broadcast_to(self.normal, (len(self.dofs), v.shape[1]))
        vn = np.einsum("nd,nd->n", v[self.dofs], n)
        v[self.dofs] -= vn[:, None] * n


@dataclass(frozen=True)
class Prescribed:
    """Grid velocity components held at given values at ``dofs`` (a moving rigid plate):
    ``velocity`` (d,), NaN entries leave that component free."""

    dofs: npt.NDArray[np.int32]
    velocity: npt.NDArray
    needs_positions: ClassVar[bool] = False
    zero_components: ClassVar[bool] = False
    kind: ClassVar[str] = "prescribed velocities"

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        held = np.flatnonzero(np.isfinite(self.velocity))
        v[np.ix_(self.dofs, held)] = self.velocity[held]


@dataclass(frozen=True)
class Friction:
    r"""A rigid wall with Coulomb friction (coefficient ``mu``) at ``dofs``, outward ``normal``
    (unit, (d,), or one per dof (len(dofs), d)). Where the grid velocity moves into the wall (:math:`v_n = v \cdot n > 0`),
    its normal part is removed and the tangential part reduced by the friction that normal
    impulse can carry,

    .. math::
        v_t \leftarrow v_t \max\Big(0,\ 1 - \mu \frac{v_n}{|v_t|}\Big),

    (sticking where that reaches 0); where it leaves the wall the velocity is free (Bardenhagen,
    Brackbill and Sulsky, Comput. Methods Appl. Mech. Engrg. 187, 2000). Applied to the updated
    grid velocity of every step: over a step the wall takes the normal momentum
    :math:`m_i v_n` and at most :math:`\mu m_i v_n` of the tangential one.

    ``gap``: a node also has to *touch* the wall, a position check in the manner of Nairn,
    Bardenhagen and Smith (2018): the body's centre of mass as the node sees it,
    :math:`\bar x_i = \sum_p M_p N_{ip} x_p / \sum_p M_p N_{ip}`, lies within ``gap`` of the
    wall, its depth :math:`\delta_i = \text{gap} - (x_i - \bar x_i) \cdot n > 0` (a body filling
    the node's cells on a grid of spacing :math:`h` normal to the wall has it at :math:`h/3`;
    0.375 h with 2 particles per cell). Without it every node whose velocity points into the
    wall is held, also the nodes a curved body only approaches: a rolling disk then meets a wall
    across the :math:`\sim\sqrt{8 R h}` of nodes its bottom cells touch, which stops its rotation.

    With a gap the normal momentum the wall takes, :math:`P = \sum_{i \in H} m_i v_{n,i}` over
    the touching nodes :math:`H` that move into it, is shared by all touching nodes of the same
    patch :math:`T` (a connected set of them along the wall: one per place a body touches it)
    in proportion to their mass and depth,

    .. math::
        \Delta v_{n,i} = P\, \frac{\delta_i}{\sum_{j \in T} m_j \delta_j}, \qquad
        v_{n,i} \leftarrow v_{n,i} - \Delta v_{n,i}, \qquad
        v_{t,i} \leftarrow v_{t,i} \max\Big(0,\ 1 - \mu \frac{\Delta v_{n,i}}{|v_{t,i}|}\Big),

    so that the patch takes the same normal momentum as node by node, centred where the body
    is deepest rather than at the nodes that happen to move into the wall. Node by node, a body
    that turns on the wall is released behind its contact point and held ahead of it, and the
    held nodes' normal impulses brake its rotation with a lever arm of about a cell: a disk
    rolled only from mu = 0.25-0.3 at 8 cells per radius instead of tan(theta)/3 = 0.19
    (docs/contact.md). A node ahead keeps part of its motion into the wall until its depth
    takes its share; the gap still frees every node the body does not touch.

    ``points`` are the dofs' coordinates and ``patches`` finds the patches among them
    (:class:`fempm.boundary.patches.Patches`; ``gap`` needs both). A wall with a gap needs the nodal centres of mass and masses (:attr:`needs_positions`):
    the solver (the generic or the compiled step) maps them each step and passes them to
    :meth:`apply` (collective then)."""

    dofs: npt.NDArray[np.int32]
    normal: npt.NDArray
    mu: float
    gap: float | None = None
    points: npt.NDArray | None = None
    patches: Patches | None = None

    zero_components: ClassVar[bool] = False
    kind: ClassVar[str] = "a frictional wall"

    @property
    def needs_positions(self) -> bool:
        return self.gap is not None

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        """Friction on the velocities ``v`` (dofs, d); ``centroids``: the nodal centres of mass
        and masses, needed with a ``gap``."""
        vd = v[self.dofs]
        n = np.broadcast_to(self.normal, vd.shape)  # one normal, or one per dof (a tagged wall)
        vn = np.einsum("kd,kd->k", vd, n)
        vt = vd - vn[:, None] * n
        if self.gap is None:  # each node moving into the wall gives up its normal velocity
            held, dvn = vn > 0, vn
        else:  # the touching nodes share the normal momentum of their patch by depth
            if centroids is None:
                raise ValueError("a friction wall with a gap needs the nodal centres of mass and masses")
            depth = self.gap - np.einsum("kd,kd->k", self.points - centroids.centre[self.dofs], n)  # NaN: no mass
            held = depth > 0
            depth = np.where(held, depth, 0.0)
            t = np.flatnonzero(held)  # every touching node takes a share, those moving in give
            dvn = np.zeros_like(vn)
            dvn[t] = depth_shares(self.patches.sums, self.dofs[t], centroids.mass[self.dofs[t]],
                                  np.maximum(vn[t], 0.0), depth[t])  # collective
        v[self.dofs] = np.where(held[:, None], coulomb(vt, vn, n, dvn, self.mu), vd)


def _axis(normal: npt.NDArray) -> int | None:
    """The axis of a single unit normal along a coordinate axis, else None."""
    n = np.asarray(normal)
    if n.ndim != 1 or np.count_nonzero(n) != 1 or abs(n[np.flatnonzero(n)[0]]) != 1.0:
        return None
    return int(np.flatnonzero(n)[0])


def locate_dofs(V: dolfinx.fem.FunctionSpace, where: Callable[[npt.NDArray], npt.NDArray]) -> npt.NDArray[np.int32]:
    """(Block) dofs where ``where(x)`` holds (x of shape (3, n)): at the dof positions for
    Lagrange spaces with point evaluation; for others (Bernstein), the dofs of every mesh
    entity (vertex, edge, face, cell) whose vertices all satisfy ``where``."""
    if V.element.interpolation_ident:  # dofs are point values
        return np.asarray(dolfinx.fem.locate_dofs_geometrical(V, where), dtype=np.int32)
    mesh = V.mesh
    found = []
    for dim in range(mesh.topology.dim + 1):
        mesh.topology.create_entities(dim)
        entities = dolfinx.mesh.locate_entities(mesh, dim, where)
        mesh.topology.create_connectivity(dim, mesh.topology.dim)
        found.append(np.asarray(dolfinx.fem.locate_dofs_topological(V, dim, entities), dtype=np.int32))
    return np.unique(np.concatenate(found))


def fixed(V: dolfinx.fem.FunctionSpace, where: Callable[[npt.NDArray], npt.NDArray]) -> Fixed:
    """A no-slip condition: every velocity component zero at the dofs where ``where(x)`` holds.

    Args:
        V: The velocity space.
        where: A predicate on the dof coordinates x of shape (3, n) (see :func:`locate_dofs`).

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])``.
    """
    return Fixed(locate_dofs(V, where))


def _unit_normal(normal, d: int, what: str) -> npt.NDArray:
    n = np.asarray(normal, dtype=np.float64)
    if n.shape != (d,) or not np.all(np.isfinite(n)) or not np.linalg.norm(n) > 0:
        raise ValueError(f"{what} needs a finite, non-zero normal with {d} components (got {normal!r})")
    return n / np.linalg.norm(n)


def slip(V: dolfinx.fem.FunctionSpace, where: Callable[[npt.NDArray], npt.NDArray], normal) -> Slip:
    """A frictionless wall: the velocity component along ``normal`` zero at the dofs where
    ``where(x)`` holds.

    Args:
        V: The velocity space.
        where: A predicate on the dof coordinates x of shape (3, n).
        normal: The wall's normal (d,), any length; axis-aligned normals constrain one
            component, others a direction.

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])``.
    """
    return Slip(locate_dofs(V, where), _unit_normal(normal, V.mesh.geometry.dim, "slip"))


def prescribed(V: dolfinx.fem.FunctionSpace, where: Callable[[npt.NDArray], npt.NDArray], velocity) -> Prescribed:
    """A moving rigid plate: the grid velocity held at ``velocity`` at the dofs where ``where(x)``
    holds.

    Args:
        V: The velocity space.
        where: A predicate on the dof coordinates x of shape (3, n).
        velocity: The velocity (d,); NaN components stay free (``(nan, -0.1)``: a smooth plate
            moving down at 0.1).

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])``.
    """
    u = np.asarray(velocity, dtype=np.float64)
    d = V.mesh.geometry.dim
    if u.shape != (d,) or np.any(np.isinf(u)) or np.all(np.isnan(u)):
        raise ValueError(f"prescribed needs a velocity with {d} components, finite or NaN (free), not all NaN "
                         f"(got {velocity!r})")
    return Prescribed(locate_dofs(V, where), u)


def friction(V: dolfinx.fem.FunctionSpace, where: Callable[[npt.NDArray], npt.NDArray], normal,
             mu: float, gap: float | None = None) -> Friction:
    """A rigid wall with Coulomb friction at the dofs where ``where(x)`` holds.

    Where the grid velocity moves into the wall its normal part is removed and the tangential
    part reduced by at most ``mu`` times that normal change (:class:`Friction`); where it leaves,
    the velocity is free.

    Args:
        V: The velocity space.
        where: A predicate on the dof coordinates x of shape (3, n).
        normal: The wall's normal (d,), pointing out of the body into the wall.
        mu: The friction coefficient, >= 0 (0: a slip wall the body may leave).
        gap: Hold only the nodes the body touches (a length: half the cell size normal to the
            wall is a good value); None holds every node moving into the wall.

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])``.

    Raises:
        ValueError: ``mu`` negative or not finite, ``gap`` not positive.
    """
    _check_mu(mu)
    if gap is not None and not 0.0 < gap < np.inf:
        raise ValueError(f"friction needs a finite gap > 0 or None (got {gap!r})")
    d = V.mesh.geometry.dim
    dofs = locate_dofs(V, where)
    if gap is None:
        return friction_wall(dofs, _unit_normal(normal, d, "friction"), mu)
    if not V.element.interpolation_ident:
        raise ValueError("a friction wall with a gap needs a Lagrange space whose dofs are point values")
    points = V.tabulate_dof_coordinates()[dofs, :d]
    return Friction(dofs, _unit_normal(normal, d, "friction"), float(mu), float(gap), points,
                    Patches.of_space(V, dofs))


def _check_mu(mu: float) -> None:
    if not 0.0 <= mu < np.inf:
        raise ValueError(f"friction needs a finite coefficient mu >= 0 (got {mu!r})")


def friction_wall(dofs: npt.NDArray[np.int32], normal: npt.NDArray, mu: float) -> Friction:
    """A :class:`Friction` wall without a gap at ``dofs`` with unit ``normal`` ((d,) or one per
    dof), ``mu`` checked (finite, >= 0)."""
    _check_mu(mu)
    return Friction(dofs, normal, float(mu))


def fixed_on_facets(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, tag: int) -> Fixed:
    """Fixed dofs on the facets of a gmsh physical group."""
    mesh = V.mesh
    mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
    dofs = dolfinx.fem.locate_dofs_topological(V, mesh.topology.dim - 1, facet_tags.find(tag))
    return Fixed(np.asarray(dofs, dtype=np.int32))
