r"""Absorbing boundaries: viscous dashpots on the grid (Lysmer and Kuhlemeyer 1969).

A boundary of a medium of density :math:`\rho`, P-wave speed :math:`c_p` and S-wave speed
:math:`c_s` absorbs the waves that meet it at normal incidence when it carries the tractions

.. math::
    \mathbf t = -\rho c_p (\mathbf v \cdot \mathbf n)\, \mathbf n - \rho c_s \big(\mathbf v -
    (\mathbf v \cdot \mathbf n)\, \mathbf n\big),

those of the medium that would continue beyond it. On the grid each boundary node :math:`i`
takes the dashpots :math:`C_{n,i} = \rho c_p A_i` and :math:`C_{t,i} = \rho c_s A_i` with
:math:`A_i = \int_\Gamma N_i\, ds` its share of the boundary (assembled with DOLFINx: any degree
and variant) and :math:`\mathbf n_i` the facet normals averaged at the node
(:func:`fempm.boundary.tagged.facet_normals`). They act on the step's velocity update,
implicitly (backward Euler), so that no time step limit comes from them:

.. math::
    m_i (\mathbf v_i^+ - \mathbf v_i) = \Delta t (\mathbf f_i - C_i \mathbf v_i^+)
    \quad\Longrightarrow\quad v_{n,i}^+ = \frac{v_{n,i}^*}{1 + \Delta t\, C_{n,i}/m_i},\quad
    \mathbf v_{t,i}^+ = \frac{\mathbf v_{t,i}^*}{1 + \Delta t\, C_{t,i}/m_i},

with :math:`\mathbf v^*` the updated velocity without them and :math:`m_i` the lumped nodal
mass. The velocity mapped from the particles is left free.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import dolfinx.fem
import dolfinx.la
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
import ufl

from fempm.boundary.tagged import boundary_only, facet_normals, tagged_facets
from fempm.transfer.centres import NodalCentres

__all__ = ["Dashpot", "absorbing", "nodal_boundary_shares"]


@dataclass(frozen=True)
class Dashpot:
    """Viscous dashpots at ``dofs`` (the module): unit ``normal`` (len(dofs), d), normal and
    tangential coefficients ``normal_coefficient``, ``tangential_coefficient`` (len(dofs),),
    :math:`\\rho c_p A_i` and :math:`\\rho c_s A_i`."""

    dofs: npt.NDArray[np.int32]
    normal: npt.NDArray
    normal_coefficient: npt.NDArray
    tangential_coefficient: npt.NDArray
    #: the nodal masses come with the step's nodal centres of mass
    needs_positions: ClassVar[bool] = True
    zero_components: ClassVar[bool] = False
    kind: ClassVar[str] = "absorbing dashpots"
    #: it acts on the velocity update (:meth:`on_update`)
    acts_on_update: ClassVar[bool] = True

    def apply(self, v: npt.NDArray, centroids: NodalCentres | None = None) -> None:
        """The mapped velocity is free: the dashpots act on the update (:meth:`on_update`)."""

    def on_update(self, v: npt.NDArray, centroids: NodalCentres, dt: float) -> None:
        """The dashpots on the updated velocity ``v`` (dofs, d) of a step ``dt``, in place."""
        m = centroids.mass[self.dofs]
        with_mass = m > 0.0
        dofs, m = self.dofs[with_mass], m[with_mass]
        n = self.normal[with_mass]
        vd = v[dofs]
        vn = np.einsum("kd,kd->k", vd, n)
        vt = vd - vn[:, None] * n
        v[dofs] = (vn / (1.0 + dt * self.normal_coefficient[with_mass] / m))[:, None] * n \
            + vt / (1.0 + dt * self.tangential_coefficient[with_mass] / m)[:, None]


def nodal_boundary_shares(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags,
                          value: int) -> npt.NDArray:
    r""":math:`A_i = \int_{\Gamma} N_i\, ds` over the facets tagged ``value``, for every block dof
    of ``V`` (owned and ghost; summed over ranks). Collective."""
    ds = ufl.Measure("ds", domain=V.mesh, subdomain_data=facet_tags)
    n = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    if V.num_sub_spaces:
        Q, to_V = V.sub(0).collapse()
        to_V = np.asarray(to_V).ravel()  # (dolfinx may give it as a nested list)
        test = ufl.TestFunction(Q)
    else:  # one component (an interval mesh's velocity): the space is its own component
        Q, to_V = V, np.arange(n) * V.dofmap.index_map_bs
        test = ufl.TestFunction(Q)[0] if len(V.value_shape) else ufl.TestFunction(Q)
    share = dolfinx.fem.assemble_vector(dolfinx.fem.form(test * ds(int(value))))
    share.scatter_reverse(dolfinx.la.InsertMode.add)
    share.scatter_forward()
    out = np.zeros(n)
    out[to_V // V.dofmap.index_map_bs] = share.array[: len(to_V)]
    return out


def absorbing(V: dolfinx.fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags | None = None,
              value: int | None = None, rho: float = 1.0, cp: float = 1.0, cs: float = 0.0, *,
              where: Callable[[npt.NDArray], npt.NDArray] | None = None) -> Dashpot:
    r"""An absorbing boundary on the facets tagged ``value`` (or on the boundary facets where
    ``where(x)`` holds): the dashpots of the module.

    Args:
        V: The velocity space.
        facet_tags: Facet tags of ``V``'s mesh (gmsh physical groups).
        value: The tag.
        rho: The density of the medium beyond the boundary.
        cp: Its P-wave speed, :math:`\sqrt{(\lambda + 2\mu)/\rho}`.
        cs: Its S-wave speed, :math:`\sqrt{\mu/\rho}` (0: no tangential dashpot).
        where: Instead of tags, a predicate on the facets' points x (3, n), as
            ``dolfinx.mesh.locate_entities_boundary``.

    Returns:
        The condition, for ``ExplicitSolver(bcs=[...])`` (the explicit step).

    Raises:
        ValueError: A negative or non-finite impedance :math:`\rho c_p`, :math:`\rho c_s`, both
            or neither of tags and ``where``, and the errors of
            :func:`fempm.boundary.tagged.tagged_facets`.

    Note:
        Collective.
    """
    for name, speed in (("cp", cp), ("cs", cs)):
        z = rho * speed
        if not (np.isfinite(z) and z >= 0.0):
            raise ValueError(f"absorbing boundary: the dashpot impedance rho*{name} = {rho:g}*{speed:g} = {z:g} "
                             "must be a finite number >= 0")
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    if (where is None) == (facet_tags is None):
        raise ValueError("an absorbing boundary takes facet tags and a tag value, or where (one of them)")
    if where is not None:
        mesh.topology.create_connectivity(fdim, mesh.topology.dim)
        found = dolfinx.mesh.locate_entities_boundary(mesh, fdim, where)
        if not mesh.comm.allreduce(len(found)):
            raise ValueError("absorbing boundary: where(x) holds on no boundary facet of the mesh")
        facet_tags, value = dolfinx.mesh.meshtags(mesh, fdim, found, np.ones(len(found), dtype=np.int32)), 1
    facets = tagged_facets(mesh, facet_tags, value)
    boundary_only(mesh, facets, value, "an absorbing boundary")
    dofs, normals = facet_normals(V, facets)
    area = nodal_boundary_shares(V, facet_tags, value)[dofs]
    return Dashpot(dofs, normals, rho * cp * area, rho * cs * area)
