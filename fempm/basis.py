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

    def __init__(
        self, V: dolfinx.fem.FunctionSpace, particles: Particles, *, gradients: bool = False, domain=None
    ):
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
        self.domain = domain
        self.gradients: npt.NDArray | None = None
        if domain is None or getattr(domain, "name", "") == "point":
            cells, X = particles.cells, particles.X
            self.cells: npt.NDArray[np.int32] | None = cells  # one cell per particle
            tab = element.tabulate(1 if gradients else 0, np.ascontiguousarray(X))[..., 0]
            self.values: npt.NDArray = tab[0]  # S, (n, ndofs)
            self.dofs: npt.NDArray[np.int32] = np.asarray(V.dofmap.list)[cells]
            if gradients:
                K = particles.locator.geometry.inverse_jacobian(cells, X)  # (n, tdim, gdim)
                self.gradients = np.transpose(tab[1:], (1, 2, 0)) @ K  # (n, k, tdim) @ (n, tdim, gdim)
        else:
            self.cells = None
            self._averaged(V, particles, domain, gradients)

    def _averaged(self, V, particles: Particles, domain, gradients: bool) -> None:
        r"""Domain-averaged :math:`\langle N_i \rangle_p` and :math:`\langle \nabla N_i \rangle_p`
        from the domain's sample points (:mod:`fempm.domains`), with each particle's entries
        for the same dof summed: ``values`` (n, K), ``gradients`` (n, K, d), ``dofs`` (n, K),
        K the largest number of distinct dofs a particle touches (unused slots hold 0)."""
        smp = domain.samples(particles)
        n, q, d = smp.x.shape
        locator = particles.sample_locator
        xs = smp.x.reshape(n * q, d)
        cells, X = locator.relocate(xs, np.repeat(particles.cells, q))
        need_grad = gradients and smp.grad_from_values
        k = self.element.dim
        N = np.empty((n * q, k))
        dofs = np.empty((n * q, k), dtype=np.int32)
        dN = np.empty((n * q, k, d)) if need_grad else None
        here = np.flatnonzero(cells >= 0)
        tab = self.element.tabulate(1 if need_grad else 0, np.ascontiguousarray(X[here]))[..., 0]
        N[here] = tab[0]
        dofs[here] = np.asarray(V.dofmap.list)[cells[here]]
        if need_grad:
            K = locator.geometry.inverse_jacobian(cells[here], X[here])
            dN[here] = np.transpose(tab[1:], (1, 2, 0)) @ K
        self._remote_samples(particles, domain, xs, cells, q, need_grad, N, dofs, dN)
        self.sample_values, self.sample_dofs = N.reshape(n, q, k), dofs.reshape(n, q, k)
        w = smp.w.reshape(n * q)
        vals = (N * w[:, None]).reshape(n, q * k)
        dofs = dofs.reshape(n, q * k)
        grads = None
        if gradients:
            grads = dN * w[:, None, None] if need_grad else np.zeros((n * q, k, d))
            if smp.g is not None:
                grads = grads + N[:, :, None] * smp.g.reshape(n * q, 1, d)
            grads = grads.reshape(n, q * k, d)
        # sum each particle's entries per distinct dof
        order = np.argsort(dofs, axis=1, kind="stable")
        ds = np.take_along_axis(dofs, order, axis=1)
        new = np.ones(ds.shape, dtype=bool)
        new[:, 1:] = ds[:, 1:] != ds[:, :-1]
        uid = np.cumsum(new, axis=1) - 1
        Ku = int(uid.max(initial=0)) + 1
        flat = (np.arange(n)[:, None] * Ku + uid).ravel()
        self.values = np.bincount(flat, weights=np.take_along_axis(vals, order, axis=1).ravel(),
                                  minlength=n * Ku).reshape(n, Ku)
        self.dofs = np.repeat(ds[:, :1], Ku, axis=1) if n else np.zeros((0, Ku), dtype=np.int32)
        self.dofs.reshape(-1)[flat] = ds.ravel()
        self.dofs = self.dofs.astype(np.int32)
        if grads is not None:
            gs = np.take_along_axis(grads, order[:, :, None], axis=1)
            self.gradients = np.stack(
                [np.bincount(flat, weights=gs[:, :, c].ravel(), minlength=n * Ku) for c in range(d)], axis=-1
            ).reshape(n, Ku, d)

    def _remote_samples(self, particles: Particles, domain, xs, cells, q, need_grad, N, dofs, dN) -> None:
        """Fill the rows of sample points outside this rank's owned and ghost cells from the
        ranks that own them (:mod:`fempm.halo`), extending :attr:`index_map` by their dofs.
        Collective; sample points in no cell of any rank are an :class:`OutsideMeshError` on
        every rank."""
        from fempm.location import OutsideMeshError

        comm = particles.comm
        lost = np.flatnonzero(cells < 0)
        nlost = comm.allreduce(len(lost)) if comm.size > 1 else len(lost)
        if nlost == 0:
            return
        missing = lost
        if comm.size > 1:
            from fempm.halo import extend_index_map, remote_rows

            rows = remote_rows(particles.locator, self.element, self.V, xs[lost], need_grad)
            hit = lost[rows.found]
            self.index_map, local = extend_index_map(self.index_map, rows.gdofs[rows.found], rows.owners[rows.found])
            N[hit], dofs[hit] = rows.N[rows.found], local
            if need_grad:
                dN[hit] = rows.dN[rows.found]
            missing = lost[~rows.found]
        nmissing = comm.allreduce(len(missing)) if comm.size > 1 else len(missing)
        if nmissing:
            ex = np.concatenate(comm.allgather(xs[missing][:3])) if comm.size > 1 else xs[missing][:3]
            ids = np.concatenate(comm.allgather(particles.ids[missing // q][:5])) if comm.size > 1 else particles.ids[missing // q]
            raise OutsideMeshError(
                f"{nmissing} sample point(s) of {domain.name} particle domains lie outside the mesh, "
                f"e.g. at {ex[:3].tolist()}; particle ids {np.unique(ids)[:5].tolist()}"
            )

    @property
    def extended(self) -> bool:
        """Whether the dofs include extra ghosts for remote sample points (:mod:`fempm.halo`)."""
        return self.index_map is not self.V.dofmap.index_map

    @property
    def num_dofs_space(self) -> int:
        """Owned + ghost (block) dofs of the space itself (the length of ``Function.x`` / bs)."""
        imap = self.V.dofmap.index_map
        return imap.size_local + imap.num_ghosts

    def update_ghosts(self, nodal: npt.NDArray) -> npt.NDArray:
        """Nodal data (space dofs or all local dofs, k) with every ghost, the extra ones
        included, set from its owner; returns (:attr:`num_dofs_local`, k). Without extra
        ghosts the input is returned as is."""
        if not self.extended and len(nodal) == self.num_dofs_local:
            return nodal
        k = nodal.shape[1]
        vec = dolfinx.la.vector(self.index_map, bs=k)
        vec.array[: nodal.size] = nodal.ravel()
        vec.scatter_forward()
        return vec.array.reshape(-1, k).copy()

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

    def gather_samples(self, nodal: npt.NDArray) -> npt.NDArray:
        r"""Nodal (ndofs, k) data at the domain's sample points, :math:`f(y_{pq}) = \sum_a
        N_a(y_{pq}) F_{d(pq, a)}`, shape (n, q, k) (e.g. the velocity of CPDI2 corners)."""
        if self.cells is not None:  # point particles: the sample is the particle
            return self.gather(nodal)[:, None, :]
        if len(nodal) < self.num_dofs_local:
            nodal = self.update_ghosts(nodal)
        return np.einsum("nqa,nqak->nqk", self.sample_values, nodal[self.sample_dofs])

    def gather(self, nodal: npt.NDArray) -> npt.NDArray:
        r"""G2P: :math:`f_p = \sum_a S[p, a]\, F_{d(p,a)}` for nodal (ndofs, k) data -> (n, k)."""
        if len(nodal) < self.num_dofs_local:  # the space's dofs: fetch the extra ghosts
            nodal = self.update_ghosts(nodal)
        return np.einsum("na,nak->nk", self.values, nodal[self.dofs])
