r"""The particle-grid operator: basis values and gradients of a DOLFINx space at the particles.

For particle :math:`p` in cell :math:`c_p` with reference coordinates :math:`X_p`:

.. math::
    S[p, a] = N_{d(p,a)}(x_p) = \hat N_a(X_p), \qquad
    G[p, a, :] = \nabla N_{d(p,a)}(x_p) = \nabla_X \hat N_a(X_p)\, K(X_p),

with :math:`d(p, a)` = ``dofs[p, a]`` the local (block) dof of the cell's a-th basis function
(``V.dofmap.list[c_p]``) and :math:`K = J^{-1}`. ``S`` and ``G`` are stored dense per particle
(n, ndofs_per_cell) with their dof lists: the sparse particle-to-dof operator in row form.
Vector (blocked) spaces share the scalar operator: component ``i`` of dof ``d`` is entry
``d * bs + i`` of the function's array.
"""

from __future__ import annotations

import basix
import dolfinx
import numpy as np
import numpy.typing as npt

from fempm.particles import Particles


def is_nonnegative(element: basix.finite_element.FiniteElement) -> bool:
    """Whether every basis function is non-negative (linear Lagrange or Bernstein)."""
    return element.degree <= 1 or element.lagrange_variant == basix.LagrangeVariant.bernstein


class ParticleBasis:
    """``S`` (values), optional ``G`` (gradients) and dof lists of ``V`` at the particles.

    Parameters
    ----------
    V:
        A scalar or blocked Lagrange (any variant, including Bernstein) space on the particles'
        mesh.
    particles:
        Located particles.
    gradients:
        Also tabulate physical gradients ``G`` (n, ndofs_per_cell, gdim).
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, particles: Particles, *, gradients: bool = False):
        if V.mesh is not particles.mesh:
            raise ValueError("the function space and the particles live on different meshes")
        element = V.element.basix_element
        if element.family != basix.ElementFamily.P:
            raise NotImplementedError(f"fempm supports Lagrange-family spaces, not {element.family.name}")
        if V.element.needs_dof_transformations:
            raise NotImplementedError("spaces whose dofs need transformations are not supported")
        self.V = V
        self.element = element
        self.bs = V.dofmap.index_map_bs
        self.index_map = V.dofmap.index_map
        self.nonnegative = is_nonnegative(element)
        cells, X = particles.cells, particles.X
        tab = element.tabulate(1 if gradients else 0, np.ascontiguousarray(X))[..., 0]
        self.values: npt.NDArray = tab[0]  # S, (n, ndofs)
        self.dofs: npt.NDArray[np.int32] = np.asarray(V.dofmap.list)[cells]
        self.gradients: npt.NDArray | None = None
        if gradients:
            K = particles.locator.geometry.inverse_jacobian(cells, X)  # (n, tdim, gdim)
            self.gradients = np.transpose(tab[1:], (1, 2, 0)) @ K  # (n, k, tdim) @ (n, tdim, gdim)

    @property
    def num_dofs_local(self) -> int:
        """Owned + ghost (block) dofs on this rank."""
        return self.index_map.size_local + self.index_map.num_ghosts

    def scatter(self, weights: npt.NDArray, *, values: npt.NDArray | None = None) -> npt.NDArray:
        r"""Local P2G sums :math:`\sum_p w_p S[p, a]` into (owned + ghost) dofs, shape (ndofs, k).

        ``weights`` is (n,) or (n, k); ``values`` replaces ``S`` (e.g. ``S**2``). Ghost entries
        are partial sums (see :func:`fempm.transfer.p2g` for the reduced result).
        """
        S = self.values if values is None else values
        w = np.asarray(weights, dtype=np.float64)
        w2 = w[:, None] if w.ndim == 1 else w.reshape(w.shape[0], int(np.prod(w.shape[1:])))
        return self.scatter_contributions(S[:, :, None] * w2[:, None, :])

    def scatter_contributions(self, contrib: npt.NDArray) -> npt.NDArray:
        """Sum per-particle, per-local-dof contributions (n, ndofs_per_cell, k) into (owned +
        ghost) dofs, shape (ndofs, k); ghost entries are partial sums."""
        nd = self.num_dofs_local
        idx = self.dofs.ravel()
        out = np.empty((nd, contrib.shape[2]))
        for c in range(contrib.shape[2]):  # loop over value components, not particles
            out[:, c] = np.bincount(idx, weights=contrib[:, :, c].ravel(), minlength=nd)
        return out

    def gather(self, nodal: npt.NDArray) -> npt.NDArray:
        r"""G2P: :math:`f_p = \sum_a S[p, a]\, F_{d(p,a)}` for nodal (ndofs, k) data -> (n, k)."""
        return np.einsum("na,nak->nk", self.values, nodal[self.dofs])
