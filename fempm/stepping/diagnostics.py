r"""Diagnostics of a particle state: the Cauchy stress on the grid and the energies and
momentum of the particles."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import basix.ufl
import dolfinx.fem
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fempm.materials.linear_elastic import LinearElastic
from fempm.particles.particle_set import Particles
from fempm.stepping.laws import every, law_state, material_groups
from fempm.stepping.options import StepOptions
from fempm.transfer import affine
from fempm.transfer.basis import is_nonnegative
from fempm.transfer.projection import Projector

__all__ = ["angular_columns", "energies", "energy_row", "grid_stress", "momentum_scale", "small_strain_rotation", "strain_energy",
           "stress_space"]


def stress_space(V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.FunctionSpace:
    """The tensor-valued space of ``V``'s element (family, degree, variant) on its mesh."""
    el = V.element.basix_element
    d = V.mesh.geometry.dim
    return dolfinx.fem.functionspace(
        V.mesh, basix.ufl.element(el.family, el.cell_type, el.degree, el.lagrange_variant, shape=(d, d)))


def grid_stress(space: dolfinx.fem.FunctionSpace, particles: Particles, options: StepOptions,
                mass: Literal["lumped", "consistent"] | None = None) -> dolfinx.fem.Function:
    r"""The particles' Cauchy stress projected on ``space`` (:func:`stress_space`) as a
    per-volume field with the particle domains of ``options``: lumped,

    .. math::
        \sigma_i = \frac{\sum_p V_p \langle N_i \rangle_p \sigma_p}{\sum_p V_p \langle N_i \rangle_p},

    or the volume-weighted least-squares projection (``mass="consistent"``, rim dofs lumped as in
    the loop). The default is lumped where the basis is non-negative (P1/Q1, Bernstein) and
    consistent otherwise (P2 Lagrange, whose lumped vertex masses can vanish).

    Note:
        Collective.
    """
    p = particles
    d = p.gdim
    if mass is None:
        mass = "lumped" if is_nonnegative(space.element.basix_element) else "consistent"
    proj = Projector(space, p, mass=mass, weight="volume", domain=options.particle_domain,
                     lump_below=options.lump_below,  # only a mass that couples dofs lumps rows
                     petsc_options_prefix=options.petsc_options_prefix + "stress_")
    out = proj.project(p.fields["sigma"].reshape(len(p), d * d))
    out.name = "grid_stress"
    return out


def strain_energy(particles: Particles, materials: Sequence, which: Sequence[bool] | None = None) -> float:
    r"""This rank's strain energy :math:`\sum_p V_p^0 W_p` of the laws ``which`` selects (by
    body index; None: every law)."""
    f = particles.fields
    strain = 0.0
    for b, (mat, idx) in enumerate(material_groups(f, materials)):
        if which is not None and not which[b]:
            continue
        at = every(idx, len(particles))
        if getattr(mat, "energy_from_stress", False):  # hypoelastic: the elastic energy of the stress
            w = mat.energy_density(f["F"][at], f["sigma"][at], law_state(mat, f, idx))
        else:
            w = mat.energy_density(f["F"][at])
        strain += np.sum(f["volume0"][at] * w)
    return float(strain)


def energy_row(t: float, kinetic: float, strain: float, momentum) -> dict[str, float]:
    """The energies row of :func:`energies` from the sums over all ranks."""
    out = {"t": t, "kinetic": float(kinetic), "strain": float(strain), "total": float(kinetic + strain)}
    out.update({f"momentum_{'xyz'[i]}": float(m) for i, m in enumerate(momentum)})
    return out


def totals(particles: Particles, materials: Sequence) -> npt.NDArray:
    r"""[mass, kinetic energy, strain energy, momentum...]: :math:`\sum_p M_p`,
    :math:`\sum_p M_p |v_p|^2 / 2`, :math:`\sum_p V_p^0 W_p`, :math:`\sum_p M_p v_p`, summed
    over ranks (one reduction).

    Note:
        Collective.
    """
    p = particles
    v = p.fields["v"]
    local = np.concatenate([[p.mass.sum(), 0.5 * np.sum(p.mass * np.einsum("nd,nd->n", v, v)),
                             strain_energy(p, materials)], p.mass @ v])
    return p.comm.allreduce(local)


def energies(particles: Particles, materials: Sequence, t: float) -> dict[str, float]:
    r"""Kinetic energy :math:`\sum_p M_p |v_p|^2 / 2`, strain energy :math:`\sum_p V_p^0 W_p`,
    their total and the linear momentum :math:`\sum_p M_p v_p`, summed over ranks, at time ``t``.

    Note:
        Collective.
    """
    s = totals(particles, materials)
    return energy_row(t, s[1], s[2], s[3:])


def angular_columns(particles: Particles, spin: npt.NDArray | None = None) -> dict[str, float]:
    r"""The angular momentum about the origin, :math:`\sum_p M_p (x_p \times v_p + s_p)` over
    all ranks, with ``spin`` the particles' :math:`s_p` (the affine part the map carries,
    :func:`fempm.transfer.affine.angular_momentum`; None: the orbital part alone): the column
    ``angular_momentum`` in 2D, ``angular_momentum_x``, ``_y``, ``_z`` in 3D, none in 1D.

    Note:
        Collective.
    """
    p = particles
    if p.gdim == 1:
        return {}
    total = p.comm.allreduce(affine.angular_momentum(p.x, p.fields["v"], p.mass, spin))
    if p.gdim == 2:
        return {"angular_momentum": float(total[0])}
    return {f"angular_momentum_{c}": float(m) for c, m in zip("xyz", total)}


def momentum_scale(particles: Particles) -> float:
    r""":math:`\sum_p M_p |v_p|` over all ranks (the scale of the momentum drift). Collective."""
    p = particles
    return p.comm.allreduce(float(p.mass @ np.linalg.norm(p.fields["v"], axis=1)))


def small_strain_rotation(particles: Particles, materials: Sequence) -> float:
    r"""The largest rotation (degrees) of a particle of a small-strain law (:class:`LinearElastic`),
    the angle of :math:`R` in :math:`F = R U`: 0 without such a body. Collective."""
    from_small = [k for k, mat in enumerate(materials) if isinstance(mat, LinearElastic)]
    angle = 0.0
    f = particles.fields
    if from_small and len(particles):
        mask = np.isin(f["body"], from_small)
        if mask.any():
            u, _, vt = np.linalg.svd(f["F"][mask])
            R = u @ vt
            d = R.shape[-1]
            cos = (np.trace(R, axis1=1, axis2=2) - (d - 2)) / 2.0 if d > 1 else np.ones(len(R))
            angle = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())
    return particles.comm.allreduce(angle, op=MPI.MAX)
