r"""The affine transfers' nodal and particle sums (APIC, TPIC: :mod:`fempm.transfer.transfers`),
in numpy on a :class:`~fempm.transfer.basis.ParticleBasis`: the reference of the compiled passes.

With the dof coordinates :math:`x_i` (:func:`dof_coordinates`), the particle's offsets
:math:`r_{ip} = x_i - x_p` and its basis :math:`S_{ip}`:

* :func:`second_moments`: :math:`D_p = \sum_i S_{ip} r_{ip} r_{ip}^T`;
* :func:`grid_affine`: what G2P stores, APIC's :math:`C_p = B_p D_p^{-1}` with
  :math:`B_p = \sum_i S_{ip} v_i r_{ip}^T`, computed as :math:`L_p + (B_p - L_p D_p) D_p^{-1}`
  (:math:`L_p` itself for degree-1 point particles on affine cells, where the two are equal,
  where :math:`D_p` is too thin to invert, and on a basis with negative values, P2 Lagrange,
  whose :math:`D_p` is no second moment; exact for affine fields either way), and its spin
  :math:`s_p = \epsilon : B_p^T` (:func:`spin_of`), or TPIC's :math:`C_p = L_p`;
* :func:`carried_matrix`: the matrix P2G maps, TPIC's :math:`C_p`, APIC's :math:`C_p + W(\omega_p)`
  with the rotation :math:`W(\omega_p)` that gives it the stored spin at the particle's present
  :math:`D_p`, :math:`\epsilon : ((C_p + W(\omega_p)) D_p)^T = s_p`: in 2D
  :math:`\omega_p = (s_p - \epsilon : (C_p D_p)^T) / \operatorname{tr} D_p`, in 3D
  :math:`(\operatorname{tr} D_p\, I - D_p)\, \omega_p = s_p - \epsilon : (C_p D_p)^T`
  (0 where :math:`D_p` is too thin to carry a spin: a particle on a vertex, or on an edge in 3D);
* :func:`affine_momentum`: :math:`a_i = \sum_p M_p S_{ip} C_p r_{ip}` of the carried matrices;
* :func:`angular_momentum`: :math:`\sum_p M_p (x_p \times v_p + s_p)`;
* :func:`affine_velocity`: the grid velocity G2P takes the affine state from under
  ``affine_cutoff`` :math:`c`, :math:`v_i + w_i (v_i^+ - v_i)` with
  :math:`w_i = \min(1, m_i / (c \max_j m_j))`: a node with a small share of mass passes its
  acceleration to the particles' :math:`C_p` in proportion to that share.

Why the cutoff: FLIP and PIC weight a node's acceleration :math:`f_i / m_i` by
:math:`N_{ip}`, and :math:`m_i \ge M_p N_{ip}` bounds what a particle takes; :math:`C_p`
weighs it by :math:`\nabla N_{ip}`, which on a degree-1 basis does not vanish with
:math:`N_{ip}`. A node at a free surface holding :math:`\epsilon` of a particle's mass then
feeds :math:`1/\epsilon` of the force back into the particle's stress through :math:`C_p`, and
the loop is stable only for :math:`\Delta t \lesssim \sqrt{\epsilon}\, h / c`: APIC and TPIC
with the CFL step grow energy on fine grids (a 2D disk of 30 cells across). The cutoff bounds
the gain by :math:`1/c`; it breaks APIC's exact angular momentum by what the weak nodes'
forces carry (the particles' velocities take :math:`v^+` as without it).
"""

from __future__ import annotations

import dolfinx.fem
import numpy as np
import numpy.typing as npt

from fempm.kernels.affine import THICK, THIN
from fempm.transfer.basis import ParticleBasis
from fempm.transfer.mapping import sum_over_ranks

__all__ = ["affine_momentum", "affine_velocity", "angular_momentum", "carried_matrix", "closed_form", "dof_coordinates",
           "grid_affine", "second_moments", "spin_of", "spin_width", "weak_nodes"]



def dof_coordinates(V: dolfinx.fem.FunctionSpace) -> npt.NDArray:
    r"""The coordinates :math:`x_i` of the (block) dofs of ``V``, owned and ghost, (dofs, d):
    the coefficients of the identity :math:`x \mapsto x` in ``V``, so that
    :math:`\sum_i N_i(x) x_i = x` wherever the space holds the affine functions (the nodes of
    Lagrange spaces, the Greville points of Bernstein ones)."""
    d = V.mesh.geometry.dim
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: x[:d])
    u.x.scatter_forward()
    return u.x.array.reshape(-1, d).copy()


def spin_width(d: int) -> int:
    """The components of a spin (an angular momentum) in ``d`` dimensions: 0, 1 or 3."""
    return {1: 0, 2: 1, 3: 3}[d]


def _offsets(basis: ParticleBasis, xi: npt.NDArray, x: npt.NDArray) -> npt.NDArray:
    """:math:`r_{ap} = x_{d(p,a)} - x_p`, (n, dofs per particle, d)."""
    if len(xi) < basis.num_dofs_local:
        xi = basis.update_ghosts(xi)
    return xi[basis.dofs] - x[:, None, :]


def second_moments(basis: ParticleBasis, xi: npt.NDArray, x: npt.NDArray) -> npt.NDArray:
    r""":math:`D_p = \sum_i S_{ip} (x_i - x_p)(x_i - x_p)^T`, (n, d, d)."""
    r = _offsets(basis, xi, x)
    return np.einsum("pa,paj,pak->pjk", basis.values, r, r)


def closed_form(basis: ParticleBasis) -> bool:
    r"""Whether :math:`B_p D_p^{-1} = L_p` (degree-1 point particles on simplices of straight
    edges: :math:`(x_j - x_p) \cdot \nabla N_i = \delta_{ij} - N_{ip}` gives
    :math:`N_{ip} r_{ip} = D_p \nabla N_{ip}`)."""
    return basis.constant_gradients and basis.gradients is not None


def spin_of(B: npt.NDArray) -> npt.NDArray:
    r""":math:`\epsilon : B^T` per matrix, :math:`\sum_i S_{ip} r_{ip} \times v_i` of
    :math:`B_p = \sum_i S_{ip} v_i r_{ip}^T`: (n, 1) in 2D, (n, 3) in 3D, (n, 0) in 1D."""
    d = B.shape[1]
    if d == 1:
        return np.zeros((len(B), 0))
    if d == 2:
        return (B[:, 1, 0] - B[:, 0, 1])[:, None]
    return np.stack([B[:, 2, 1] - B[:, 1, 2], B[:, 0, 2] - B[:, 2, 0], B[:, 1, 0] - B[:, 0, 1]], axis=1)


def rotation(omega: npt.NDArray, d: int) -> npt.NDArray:
    r"""The skew matrices :math:`W(\omega)` with :math:`W r = \omega \times r`, (n, d, d)."""
    W = np.zeros((len(omega), d, d))
    if d == 2:
        W[:, 0, 1], W[:, 1, 0] = -omega[:, 0], omega[:, 0]
    elif d == 3:
        wx, wy, wz = omega.T
        W[:, 0, 1], W[:, 1, 0] = -wz, wz
        W[:, 0, 2], W[:, 2, 0] = wy, -wy
        W[:, 1, 2], W[:, 2, 1] = -wx, wx
    return W


def carried_matrix(kind: int, C: npt.NDArray, spin: npt.NDArray | None, D: npt.NDArray,
                   scale: npt.NDArray) -> npt.NDArray:
    r"""The matrix P2G maps (see the module): ``C`` for TPIC (``kind`` 2); for APIC (1) ``C``
    plus the rotation that gives it the stored ``spin`` at the present second moments ``D``
    (none where they are too thin against ``scale``, each particle's largest :math:`|r_{ip}|^2`)."""
    d = C.shape[1]
    if kind == 2 or d == 1:
        return C
    miss = spin - spin_of(C @ D)
    tr = np.trace(D, axis1=1, axis2=2)
    if d == 2:
        ok = tr > THIN * scale
        omega = np.where(ok, miss[:, 0] / np.where(ok, tr, 1.0), 0.0)[:, None]
    else:
        A = tr[:, None, None] * np.eye(3) - D
        det = np.linalg.det(A)
        ok = det > THIN * scale ** 3
        A[~ok] = np.eye(3)
        omega = np.where(ok[:, None], np.linalg.solve(A, miss[:, :, None])[:, :, 0], 0.0)
    return C + rotation(omega, d)


def affine_momentum(kind: int, C: npt.NDArray, spin: npt.NDArray | None, basis: ParticleBasis, xi: npt.NDArray,
                    x: npt.NDArray, mass: npt.NDArray) -> npt.NDArray:
    r"""The affine part of P2G, :math:`a_i = \sum_p M_p S_{ip} C_p (x_i - x_p)` of the carried
    matrices (:func:`carried_matrix`), summed over ranks, (owned + ghost dofs, d). Collective."""
    r = _offsets(basis, xi, x)
    if kind == 1:
        C = carried_matrix(kind, C, spin, np.einsum("pa,paj,pak->pjk", basis.values, r, r),
                           np.einsum("paj,paj->pa", r, r).max(axis=1, initial=0.0))
    vals = (mass[:, None] * basis.values)[:, :, None] * np.einsum("pjk,pak->paj", C, r)
    d = x.shape[1]
    n = basis.num_dofs_local
    dofs = basis.dofs.ravel()
    local = np.stack([np.bincount(dofs, weights=vals[:, :, j].ravel(), minlength=n) for j in range(d)], axis=1)
    return sum_over_ranks(basis.index_map, local)


def grid_affine(kind: int, basis: ParticleBasis, v: npt.NDArray, xi: npt.NDArray, x: npt.NDArray,
                L: npt.NDArray, v_spin: npt.NDArray | None = None) -> tuple[npt.NDArray, npt.NDArray | None]:
    r"""What G2P stores of the grid velocity ``v`` (:math:`L_p` the velocity gradient of it):
    (APIC's :math:`C_p = B_p D_p^{-1}`, its spin :math:`\epsilon : B_p^T`) for ``kind`` 1, (TPIC's
    :math:`L_p`, None) for 2; ``v_spin``: the grid velocity of the spin (None: ``v``), the
    particles' updated velocity's under ``affine_cutoff`` (:func:`affine_velocity`)."""
    if kind == 2:
        return np.array(L, copy=True), None
    if len(v) < basis.num_dofs_local:
        v = basis.update_ghosts(v)
    r = _offsets(basis, xi, x)
    B = np.einsum("pa,paj,pak->pjk", basis.values, v[basis.dofs], r)
    if v_spin is not None:
        if len(v_spin) < basis.num_dofs_local:
            v_spin = basis.update_ghosts(v_spin)
        spin = spin_of(np.einsum("pa,paj,pak->pjk", basis.values, v_spin[basis.dofs], r))
    C = np.array(L, copy=True)
    if basis.nonnegative and not closed_form(basis):  # C = L + (B - L D) D^-1 (L for an affine field)
        D = np.einsum("pa,paj,pak->pjk", basis.values, r, r)
        d = D.shape[1]
        ok = np.linalg.det(D) > THICK * (np.trace(D, axis1=1, axis2=2) / d) ** d  # else D too thin to invert: L
        D[~ok] = np.eye(D.shape[1])
        R = np.swapaxes(np.linalg.solve(D, np.swapaxes(B - L @ D, 1, 2)), 1, 2)
        C[ok] += R[ok]
    return C, spin_of(B) if v_spin is None else spin


def angular_momentum(x: npt.NDArray, v: npt.NDArray, mass: npt.NDArray, spin: npt.NDArray | None = None) -> npt.NDArray:
    r"""This rank's :math:`\sum_p M_p (x_p \times v_p + s_p)` (``spin`` None: the orbital part
    alone): (1,) in 2D, (3,) in 3D, (0,) in 1D."""
    d = x.shape[1]
    if d == 1:
        return np.zeros(0)
    orbital = (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0])[:, None] if d == 2 else np.cross(x, v)
    if spin is not None:
        orbital = orbital + spin
    return mass @ orbital


def affine_velocity(v_new: npt.NDArray, v_old: npt.NDArray, mass: npt.NDArray, weak: float) -> npt.NDArray:
    r"""The grid velocity G2P takes the particles' affine state from:
    :math:`v_i + w_i (v_i^+ - v_i)`, :math:`w_i = \min(1, m_i / m_w)` (``v_new`` itself for
    ``weak`` :math:`m_w = 0` and where no node with mass is below :math:`m_w`; see the module).

    Args:
        v_new: The updated grid velocity :math:`v^+` (dofs, d).
        v_old: The mapped grid velocity :math:`v` (dofs, d).
        mass: The lumped nodal masses :math:`m_i` of the same dofs.
        weak: :math:`m_w`, ``affine_cutoff`` times the largest nodal mass over all ranks.
    """
    nodes = weak_nodes(mass[: len(v_new)], weak)
    if not len(nodes):
        return v_new
    v = np.array(v_new, copy=True)
    w = (np.asarray(mass)[nodes] / weak)[:, None]
    v[nodes] = v_old[nodes] + w * (v_new[nodes] - v_old[nodes])
    return v


def weak_nodes(mass: npt.NDArray, weak: float) -> npt.NDArray:
    r"""The nodes with mass below ``weak`` :math:`m_w` (:func:`affine_velocity`), none for
    :math:`m_w = 0`; a node without mass is none of them (no particle reads it)."""
    m = np.asarray(mass)
    return np.flatnonzero((m > 0.0) & (m < weak)) if weak > 0.0 else np.zeros(0, dtype=np.intp)
