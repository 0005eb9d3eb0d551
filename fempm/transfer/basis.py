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

from fempm.kernels import shape as shape_kernels
from fempm.kernels.g2p import interpolate
from fempm.kernels.p2g import scatter_weighted
from fempm.particles.halo import extend_index_map, remote_box_rows, remote_rows
from fempm.particles.particle_set import Particles
from fempm.transfer.box_average import BoxIntegrator
from fempm.transfer.domains import Point, make_domain

__all__ = ["ParticleBasis", "is_nonnegative"]


def is_nonnegative(element: basix.finite_element.FiniteElement) -> bool:
    """Whether every basis function is non-negative (linear Lagrange or Bernstein)."""
    return element.degree <= 1 or element.lagrange_variant == basix.LagrangeVariant.bernstein


class ParticleBasis:
    """The basis of a space at the particles: values ``S``, optional gradients ``G`` and the dofs
    of each particle's cell (or, for particle domains, of every cell the domain touches).

    Args:
        V: A scalar or blocked Lagrange space (any variant, including Bernstein) on the
            particles' mesh.
        particles: Located particles.
        gradients: Also tabulate the physical gradients ``G`` (n, dofs per cell, gdim).
        domain: The particle domain over which the basis is averaged (a name or a
            :mod:`fempm.transfer.domains` object; default the point).

    Note:
        Collective (domain samples on other ranks are exchanged).
    """

    def __init__(
        self, V: dolfinx.fem.FunctionSpace, particles: Particles, *, gradients: bool = False, domain=None
    ):
        if V.mesh is not particles.mesh:
            raise ValueError("the function space and the particles live on different meshes")
        if isinstance(domain, str):  # a name, as StepOptions(domain=...) takes it
            domain = make_domain(domain)
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
        if domain is None or isinstance(domain, Point):
            cells, X = particles.cells, particles.X
            self.cells: npt.NDArray[np.int32] | None = cells  # one cell per particle
            geo = particles.locator.geometry
            if element.degree == 1 and particles.locator.compiled:  # closed form (fempm.kernels.shape)
                self.values, G, self.dofs = shape_kernels.cell_basis(
                    cells, X, geo.kernel_geometry[1], np.asarray(V.dofmap.list), geo.kernel_cell)
                self.gradients = G if gradients else None
                return
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
        with each particle's entries for the same dof summed: ``values`` (n, K), ``gradients``
        (n, K, d), ``dofs`` (n, K), K the largest number of distinct dofs a particle touches
        (unused slots hold 0). Exact GIMP integrates over the boxes' pieces in the cells
        (:mod:`fempm.transfer.box_average`); the other domains sum over their sample points
        (:mod:`fempm.transfer.domains`)."""
        if getattr(domain, "exact", False):
            rows = self._box_rows(V, particles, domain, gradients)
        else:
            rows = self._sample_rows(V, particles, domain, gradients)
        self.values, self.dofs, self.gradients = _dense_rows(*rows, len(particles), particles.gdim)

    def _box_rows(self, V, particles: Particles, domain, gradients: bool):
        """Rows (particle, local dof, value, gradient) of exact box averages: the integrals over
        the boxes' pieces in this rank's owned cells plus those the other ranks own
        (:func:`fempm.particles.halo.remote_box_rows`), divided by the covered volume."""

        lo, hi = domain.box(particles)
        integ = BoxIntegrator(particles.locator.geometry, self.element, V.dofmap.list, particles.locator.cell_bins)
        r = integ.integrals(lo, hi, gradients)
        box, dofs, N, dN, volume = r.box, r.dofs, r.N, r.dN, r.volume
        comm = particles.comm
        if comm.size > 1:
            far = remote_box_rows(particles.locator, integ, lo, hi, gradients, V)
            self.index_map, local = extend_index_map(self.index_map, far.gdofs, far.owners)
            box, dofs, N = np.concatenate([box, far.box]), np.concatenate([dofs, local]), np.concatenate([N, far.N])
            dN = np.concatenate([dN, far.dN]) if gradients else None
            volume = volume + far.volume
        if comm.allreduce(int(np.count_nonzero(~(volume > 0)))):
            raise ValueError("GIMP boxes of zero size or entirely outside the mesh (particle half-widths lp must be > 0)")
        N = N / volume[box]
        return box, dofs, N, (dN / volume[box, None] if gradients else None)

    def _sample_rows(self, V, particles: Particles, domain, gradients: bool):
        """Rows (particle, local dof, value, gradient) of the domain's sample points."""
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
        w = smp.w.reshape(n * q).copy()
        beyond = self._remote_samples(particles, xs, cells, need_grad, N, dofs, dN)
        if smp.beyond == "cut":  # drop the points beyond the mesh, renormalise (collective check)
            w[beyond], N[beyond], dofs[beyond] = 0.0, 0.0, 0
            if need_grad:  # not evaluated: 0, not whatever np.empty held (0 * NaN is NaN)
                dN[beyond] = 0.0
            wsum = w.reshape(n, q).sum(axis=1)
            if particles.comm.allreduce(int(np.count_nonzero(wsum <= 0))):
                raise ValueError(f"{domain.name} particle domains with no sample point inside the mesh")
            w /= np.repeat(wsum, q)
        elif smp.beyond == "clamp" and particles.comm.allreduce(len(beyond)):  # at the closest point of the mesh
            self._clamped_samples(particles, xs[beyond], beyond, need_grad, N, dofs, dN)
        self.sample_values, self.sample_dofs = N.reshape(n, q, k), dofs.reshape(n, q, k)
        vals = N * w[:, None]
        grads = None
        if gradients:
            grads = dN * w[:, None, None] if need_grad else np.zeros((n * q, k, d))
            if smp.g is not None:
                grads = grads + N[:, :, None] * smp.g.reshape(n * q, 1, d)
            grads = grads.reshape(n * q * k, d)
        return np.repeat(np.arange(n), q * k), dofs.ravel(), vals.ravel(), grads

    def _clamped_samples(self, particles: Particles, x, idx, need_grad, N, dofs, dN) -> None:
        """Rows of sample points beyond the mesh, evaluated at the closest point of the mesh
        (:meth:`fempm.particles.location.CellLocator.closest_on_mesh`, over the owned cells of every rank,
        so that the result does not depend on the partition). Collective."""
        y = particles.locator.closest_on_mesh(x)
        locator = particles.sample_locator
        cells, X = locator.locate(y)
        k, d = self.element.dim, particles.gdim
        Ny, dofs_y = np.zeros((len(y), k)), np.zeros((len(y), k), dtype=np.int32)
        dNy = np.zeros((len(y), k, d)) if need_grad else None
        here = np.flatnonzero(cells >= 0)
        tab = self.element.tabulate(1 if need_grad else 0, np.ascontiguousarray(X[here]))[..., 0]
        Ny[here], dofs_y[here] = tab[0], np.asarray(self.V.dofmap.list)[cells[here]]
        if need_grad:
            dNy[here] = np.transpose(tab[1:], (1, 2, 0)) @ locator.geometry.inverse_jacobian(cells[here], X[here])
        if len(self._remote_samples(particles, y, cells, need_grad, Ny, dofs_y, dNy)):
            raise RuntimeError("a clamped sample point was not found on the mesh")
        N[idx], dofs[idx] = Ny, dofs_y
        if need_grad:
            dN[idx] = dNy

    def _remote_samples(self, particles: Particles, xs, cells, need_grad, N, dofs, dN) -> npt.NDArray:
        """Fill the rows of sample points outside this rank's owned and ghost cells from the
        ranks that own them (:mod:`fempm.particles.halo`), extending :attr:`index_map` by their dofs.
        Returns the indices of the points that lie in no cell of any rank (beyond the mesh).
        Collective."""
        comm = particles.comm
        lost = np.flatnonzero(cells < 0)
        nlost = comm.allreduce(len(lost)) if comm.size > 1 else len(lost)
        if nlost == 0 or comm.size == 1:
            return lost

        rows = remote_rows(particles.locator, self.element, self.V, xs[lost], need_grad)
        hit = lost[rows.found]
        self.index_map, local = extend_index_map(self.index_map, rows.gdofs[rows.found], rows.owners[rows.found])
        N[hit], dofs[hit] = rows.N[rows.found], local
        if need_grad:
            dN[hit] = rows.dN[rows.found]
        return lost[~rows.found]

    @property
    def constant_gradients(self) -> bool:
        """Whether the gradients are the same at every point particle of a cell: degree 1 on affine
        simplices (interval, triangle, tetrahedron of an affine map)."""
        mesh = self.V.mesh
        return (self.cells is not None and self.element.degree == 1
                and mesh.topology.cell_name() in ("interval", "triangle", "tetrahedron")
                and mesh.geometry.cmaps[0].degree == 1)

    @property
    def extended(self) -> bool:
        """Whether the dofs include extra ghosts for remote sample points (:mod:`fempm.particles.halo`)."""
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
        are partial sums (see :func:`fempm.transfer.p2g` for the reduced result;
        :func:`fempm.kernels.p2g.scatter_weighted` sums them).
        """
        S = self.values if values is None else values
        w = np.asarray(weights, dtype=np.float64)
        w2 = w[:, None] if w.ndim == 1 else w.reshape(w.shape[0], int(np.prod(w.shape[1:])))
        return scatter_weighted(self.dofs, S, w2, self.num_dofs_local)

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
        return interpolate(self.dofs, self.values, nodal)  # (compiled, fempm.kernels.g2p)


def _dense_rows(p: npt.NDArray, dofs: npt.NDArray, vals: npt.NDArray, grads: npt.NDArray | None, n: int, d: int):
    """Rows (particle ``p``, dof, value, gradient) summed per (particle, dof) into dense
    per-particle arrays: values (n, K), dofs (n, K) and gradients (n, K, d) or None, with K
    the largest number of distinct dofs of a particle, dofs ascending; unused slots hold 0 and
    repeat the particle's first dof."""
    width = int(dofs.max(initial=0)) + 1
    uniq, inv = np.unique(p.astype(np.int64) * width + dofs, return_inverse=True)  # sorted by particle, then dof
    up = uniq // width
    count = np.bincount(up, minlength=n)
    K = int(count.max(initial=1))
    flat = up * K + np.arange(len(uniq)) - np.repeat(np.cumsum(count) - count, count)
    values = np.zeros(n * K)
    values[flat] = np.bincount(inv, weights=vals, minlength=len(uniq))
    dense = np.zeros(n * K, dtype=np.int64)
    dense[flat] = uniq % width
    dense = dense.reshape(n, K)
    dense = np.where(np.arange(K)[None, :] < count[:, None], dense, dense[:, :1])
    gradients = None
    if grads is not None:
        gradients = np.zeros((n * K, d))
        for c in range(d):  # loop over components, not particles
            gradients[flat, c] = np.bincount(inv, weights=grads[:, c], minlength=len(uniq))
        gradients = gradients.reshape(n, K, d)
    return values.reshape(n, K), dense.astype(np.int32), gradients
