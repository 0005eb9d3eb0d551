r"""The particles' blocks of the implicit step's tangent (:mod:`fempm.implicit.operator`), compiled.

* :func:`tangent_blocks`: each particle's block
  :math:`V_p \partial_m N_a \mathbb{A}_{imkl} \partial_l N_b` plus ``c`` times its mass block
  (consistent :math:`M_p N_a N_b \delta_{ik}`, or lumped on the diagonal), summed over the
  particles of a group (``slot`` (n,) of ``groups``: those of the same dofs; by default one per
  particle), in the order of :meth:`fempm.implicit.operator.IncrementOperator.pattern`, then
  zeros for the diagonal entries.
* :func:`cell_tangent_blocks`: the same where the particles of a group share their gradients
  (degree 1 on affine simplices, a group a cell): :math:`\sum_p V_p \mathbb{A}_p` and the mass
  factors summed over the group first, then one block product a group.

Each ``*_numpy`` is the reference its compiled form is tested against
(``tests/kernels/test_implicit_kernels.py``), the loops' sizes compile-time constants per
(dofs a particle, d); :func:`fempm.kernels.choice.pick` chooses.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from fempm.kernels.choice import INLINE, pick

__all__ = ["cell_tangent_blocks", "tangent_blocks"]


def tangent_blocks_numpy(gradients, values, A, volume, mass, factor: float, consistent: bool, diagonal: int,
                         slot: npt.NDArray | None = None, groups: int | None = None):
    p, k, d = gradients.shape
    VA = volume[:, None, None, None, None] * A
    K = np.einsum("paikl,pbl->paibk", np.einsum("pam,pimkl->paikl", gradients, VA, optimize=True), gradients,
                  optimize=True)
    if factor:
        eye = np.eye(d)
        if consistent:
            block = (factor * mass)[:, None, None] * values[:, :, None] * values[:, None, :]
            K += block[:, :, None, :, None] * eye[None, None, :, None, :]
        else:
            a = np.arange(k)
            K[:, a, :, a, :] += ((factor * mass)[:, None] * values).T[:, :, None, None] * eye
    if slot is not None:  # the blocks of the particles of a group summed
        summed = np.zeros((groups, (k * d) ** 2))
        np.add.at(summed, slot, K.reshape(p, -1))
        K = summed
    return np.concatenate([K.ravel(), np.zeros(diagonal)])


def cell_tangent_blocks_numpy(gradients, values, A, volume, mass, factor: float, consistent: bool, diagonal: int,
                              slot: npt.NDArray, first: npt.NDArray):
    return tangent_blocks_numpy(gradients, values, A, volume, mass, factor, consistent, diagonal, slot, len(first))


try:
    from numba import njit

    @njit(inline=INLINE)
    def contract(gradients, p, T, t, scale, B, k, d):  # pragma: no cover - compiled
        r"""``B[a, i, kk, l]`` = ``scale`` :math:`\sum_m \partial_m N_a` ``T[t, i, m, kk, l]`` of particle
        ``p``'s gradients (the left half of a block's product)."""
        for a in range(k):
            for i in range(d):
                for kk in range(d):
                    for l in range(d):
                        s = 0.0
                        for mm in range(d):
                            s += gradients[p, a, mm] * T[t, i, mm, kk, l]
                        B[a, i, kk, l] = scale * s

    @functools.cache
    def _tangent_blocks_kernel(k: int, d: int):
        """The particles' tangent blocks for ``k`` dofs per cell in dimension ``d``, the loops'
        sizes compile-time constants."""

        @njit(cache=True, error_model="numpy")
        def blocks(gradients, values, A, volume, mass, factor, consistent, diagonal, slot, groups):  # pragma: no cover
            n = gradients.shape[0]
            m = k * d
            out = np.zeros(groups * m * m + diagonal)
            B = np.empty((k, d, d, d))  # B[a, i, kk, l] = sum_m g[a, m] A[i, m, kk, l]
            for p in range(n):
                contract(gradients, p, A, p, volume[p], B, k, d)
                base = slot[p] * m * m
                for a in range(k):
                    for i in range(d):
                        row = base + (a * d + i) * m
                        for b in range(k):
                            for kk in range(d):
                                s = 0.0
                                for l in range(d):
                                    s += B[a, i, kk, l] * gradients[p, b, l]
                                out[row + b * d + kk] += s
                if factor != 0.0:
                    cm = factor * mass[p]
                    for a in range(k):
                        for i in range(d):
                            row = base + (a * d + i) * m
                            if consistent:
                                for b in range(k):
                                    out[row + b * d + i] += cm * values[p, a] * values[p, b]
                            else:
                                out[row + a * d + i] += cm * values[p, a]
            return out

        return blocks

    def tangent_blocks_numba(gradients, values, A, volume, mass, factor, consistent, diagonal, slot=None, groups=None):
        if slot is None:  # a block per particle
            slot, groups = np.arange(len(gradients)), len(gradients)
        blocks = _tangent_blocks_kernel(*gradients.shape[1:])
        return blocks(np.ascontiguousarray(gradients), np.ascontiguousarray(values), np.ascontiguousarray(A),
                      np.ascontiguousarray(volume, dtype=np.float64), np.ascontiguousarray(mass), float(factor),
                      bool(consistent), int(diagonal), np.ascontiguousarray(slot, dtype=np.int64), int(groups))

    @functools.cache
    def _cell_blocks_kernel(k: int, d: int):
        """:func:`tangent_blocks` of groups whose particles share their gradients (``first`` (groups,):
        a particle of each), ``k`` dofs a particle in dimension ``d``."""

        @njit(cache=True, error_model="numpy")
        def blocks(gradients, values, A, volume, mass, factor, consistent, diagonal, slot, first):  # pragma: no cover
            groups, m = len(first), k * d
            VA = np.zeros((groups, d, d, d, d))  # sum_p V_p A_p of each group
            Mg = np.zeros((groups, k, k))  # c sum_p M_p N_a N_b (lumped: on the diagonal, c sum_p M_p N_a)
            for p in range(len(slot)):
                g, V = slot[p], volume[p]
                for i in range(d):
                    for mm in range(d):
                        for kk in range(d):
                            for l in range(d):
                                VA[g, i, mm, kk, l] += V * A[p, i, mm, kk, l]
                if factor != 0.0:
                    cm = factor * mass[p]
                    for a in range(k):
                        if consistent:
                            for b in range(k):
                                Mg[g, a, b] += cm * values[p, a] * values[p, b]
                        else:
                            Mg[g, a, a] += cm * values[p, a]
            out = np.zeros(groups * m * m + diagonal)
            B = np.empty((k, d, d, d))
            for g in range(groups):
                p = first[g]
                contract(gradients, p, VA, g, 1.0, B, k, d)
                base = g * m * m
                for a in range(k):
                    for i in range(d):
                        row = base + (a * d + i) * m
                        for b in range(k):
                            for kk in range(d):
                                s = Mg[g, a, b] if kk == i else 0.0
                                for l in range(d):
                                    s += B[a, i, kk, l] * gradients[p, b, l]
                                out[row + b * d + kk] = s
            return out

        return blocks

    def cell_tangent_blocks_numba(gradients, values, A, volume, mass, factor, consistent, diagonal, slot, first):
        blocks = _cell_blocks_kernel(*gradients.shape[1:])
        return blocks(np.ascontiguousarray(gradients), np.ascontiguousarray(values), np.ascontiguousarray(A),
                      np.ascontiguousarray(volume, dtype=np.float64), np.ascontiguousarray(mass), float(factor),
                      bool(consistent), int(diagonal), np.ascontiguousarray(slot, dtype=np.int64),
                      np.ascontiguousarray(first, dtype=np.int64))
except ImportError:  # pragma: no cover - numba is a dependency
    tangent_blocks_numba = tangent_blocks_numpy
    cell_tangent_blocks_numba = cell_tangent_blocks_numpy

tangent_blocks = pick(tangent_blocks_numba, tangent_blocks_numpy)
cell_tangent_blocks = pick(cell_tangent_blocks_numba, cell_tangent_blocks_numpy)
