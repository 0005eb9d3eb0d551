r"""The geometry of particle domains given by their corners: corner sign vectors, axis-aligned
box corners, and the volumes, centroids and corner weights of simplex and tensor domains."""

from __future__ import annotations

import functools
import itertools

import numpy as np
import numpy.typing as npt

from fempm.kernels import corners as kc
from fempm.kernels.choice import COMPILED

__all__ = ["box_corners", "corner_signs", "domain_geometry", "domain_geometry_numpy"]


def corner_signs(d: int) -> npt.NDArray:
    """The :math:`2^d` corner sign vectors :math:`s \\in \\{\\pm 1\\}^d`, the first axis slowest."""
    return np.array(list(itertools.product((-1.0, 1.0), repeat=d)))  # (2^d, d)


@functools.cache
def _tensor_corner_rule(d: int) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray]:
    r"""Multilinear corner functions :math:`\phi_c(\xi) = \prod_a (1 + s_{ca} \xi_a)/2` on
    :math:`[-1, 1]^d` at the 2-point Gauss rule: values (G, 2^d), reference gradients
    (G, 2^d, d) and weights (G,)."""
    s = corner_signs(d)
    xi, wi = np.polynomial.legendre.leggauss(2)
    pts = np.array(list(itertools.product(xi, repeat=d)))  # (G, d)
    W = np.prod(np.array(list(itertools.product(wi, repeat=d))), axis=1)
    f = (1.0 + pts[:, None, :] * s[None, :, :]) / 2.0  # (G, k, d) factors
    phi = np.prod(f, axis=2)
    dphi = np.empty(f.shape)
    for b in range(d):
        dphi[:, :, b] = s[None, :, b] / 2.0 * np.prod(np.delete(f, b, axis=2), axis=2)
    return phi, dphi, W


def domain_geometry(corners: npt.NDArray, comm=None) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray, npt.NDArray]:
    r"""Corner weights of the linear (simplex, d + 1 corners) or multilinear (quadrilateral /
    hexahedron, :math:`2^d` corners in :func:`corner_signs` order, the first axis slowest)
    interpolant over each particle domain :math:`\Omega_p` of ``corners`` (n, k, d):

    .. math::
        w_c = \frac{1}{|\Omega_p|} \int_{\Omega_p} \phi_c, \qquad
        g_c = \frac{1}{|\Omega_p|} \int_{\Omega_p} \nabla \phi_c,

    with the volumes :math:`|\Omega_p|` and centroids :math:`\sum_c w_c y_c`. Simplices:
    :math:`w_c = 1/(d + 1)`, :math:`g_c = \nabla \lambda_c`; tensor domains: the 2-point Gauss
    rule of the isoparametric map (exact for its polynomial integrands; in 2D in closed form,
    :func:`fempm.kernels.corners.corner_geometry`). Returns (w (n, k),
    g (n, k, d), volume (n,), centroid (n, d)); a degenerate or twisted domain is a ValueError,
    raised on every rank of ``comm`` when one is given (collective)."""
    n, k, d = corners.shape
    if COMPILED and kc.AVAILABLE and k in (d + 1, 2**d):
        corners = np.ascontiguousarray(corners, dtype=np.float64)
        w, g, vol, centroid = np.empty((n, k)), np.empty((n, k, d)), np.empty(n), np.empty((n, d))
        if d == 2:  # in closed form, as the moving pass makes them
            bad, kind = kc.planar_geometry(corners, w, g, vol, centroid), "triangle" if k == 3 else "quadrilateral"
        elif k == d + 1:
            bad, kind = kc.simplex_geometry(corners, w, g, vol, centroid), "simplex"
        else:
            bad, kind = kc.tensor_geometry(corners, *_tensor_corner_rule(d), w, g, vol, centroid), \
                "quadrilateral/hexahedral"
        _report(bad, kind, comm)
        return w, g, vol, centroid
    return domain_geometry_numpy(corners, comm)


def domain_geometry_numpy(corners: npt.NDArray, comm=None) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray, npt.NDArray]:
    """The numpy formulas of :func:`domain_geometry`, the reference of its compiled kernels
    (:mod:`fempm.kernels.corners`)."""
    n, k, d = corners.shape
    if k == d + 1:
        J = np.swapaxes(corners[:, 1:, :] - corners[:, :1, :], 1, 2)  # (n, d, d), columns c_k - c_0
        det = np.linalg.det(J)
        _check_volumes(det, "simplex", comm)
        K = np.linalg.inv(J)  # row k - 1: grad lambda_k, k = 1..d
        g = np.concatenate([-K.sum(axis=1, keepdims=True), K], axis=1)
        w = np.full((n, k), 1.0 / k)
        vol = np.abs(det) / np.prod(np.arange(1, d + 1))
    elif k == 2**d:
        phi, dphi, W = _tensor_corner_rule(d)
        J = np.einsum("nci,gcb->ngib", corners, dphi)  # (n, G, d, d) dx/dxi
        det = np.linalg.det(J)
        _check_volumes(det, "quadrilateral/hexahedral", comm)
        dV = np.abs(det) * W[None, :]  # (n, G)
        vol = dV.sum(axis=1)
        w = dV @ phi / vol[:, None]
        grad = np.einsum("ngbi,gcb->ngci", np.linalg.inv(J), dphi)  # J^-T grad_xi phi
        g = np.einsum("ng,ngci->nci", dV, grad) / vol[:, None, None]
    else:
        raise ValueError(f"CPDI2 domains are simplices (d + 1 corners) or quadrilaterals/hexahedra (2^d corners): "
                         f"got {k} corners in {d}D")
    return w, g, vol, np.einsum("nc,nci->ni", w, corners)


def _check_volumes(det: npt.NDArray, kind: str, comm=None) -> None:
    """Each domain's Jacobian determinants (n,) or (n, G) must be non-zero and of one sign
    (a mirrored corner order is fine, a degenerate or twisted domain is not)."""
    det = det if det.ndim == 2 else det[:, None]
    _report(int(np.count_nonzero(~((det > 0).all(axis=1) | (det < 0).all(axis=1)))), kind, comm)


def _report(nbad: int, kind: str, comm=None) -> None:
    """A ValueError naming the ``nbad`` degenerate or twisted domains (on every rank of ``comm``)."""
    if comm is not None and comm.size > 1:
        nbad = comm.allreduce(nbad)
    if nbad:
        raise ValueError(f"{nbad} CPDI2 {kind} domain(s) are degenerate or twisted (corner Jacobian zero or "
                         "changing sign)")


def box_corners(x: npt.NDArray, half_widths: npt.NDArray) -> npt.NDArray:
    """Corners (n, 2^d, d) of axis-aligned boxes with centres ``x`` and ``half_widths`` (n, d),
    in the order :func:`domain_geometry` expects (CPDI2 domains of box particles)."""
    return x[:, None, :] + corner_signs(x.shape[1])[None, :, :] * half_widths[:, None, :]
