"""Which spaces and meshes take the compiled passes (:mod:`fempm.kernels`), and under which
kernel cell type (a key of :data:`fempm.kernels.shape.CELLS`)."""

from __future__ import annotations

import basix

from fempm.kernels.shape import AVAILABLE, BERNSTEIN2, LAGRANGE2
from fempm.meshes.geometry import SIMPLICES
from fempm.stepping.state import StepState

__all__ = ["NODAL_VARIANTS", "compiled_space", "space_refusal"]

#: the Lagrange variants whose degree-2 basis is the nodal one of the vertices and edge midpoints
NODAL_VARIANTS = (basix.LagrangeVariant.unset, basix.LagrangeVariant.equispaced, basix.LagrangeVariant.gll_warped,
                  basix.LagrangeVariant.gll_isaac, basix.LagrangeVariant.gll_centroid)


def compiled_space(solver: StepState) -> str | None:
    """The kernel cell type (:data:`fempm.kernels.shape.CELLS`) of ``solver``'s space and mesh
    where they take the compiled passes, else None: a vector degree-1 space on affine or
    multilinear cells, or a continuous degree-2 Lagrange or Bernstein space on affine
    simplices (and numba)."""
    V = solver.V
    geo = solver.particles.locator.geometry
    element = V.element.basix_element
    if not (AVAILABLE and V.dofmap.index_map_bs == solver.particles.gdim and geo.kernel_cell is not None
            and element.family == basix.ElementFamily.P and not element.discontinuous):
        return None
    if element.degree == 1:
        return geo.kernel_cell
    if element.degree == 2 and geo.affine and geo.cell_name in SIMPLICES:
        if element.lagrange_variant == basix.LagrangeVariant.bernstein:
            return geo.cell_name + BERNSTEIN2
        if element.lagrange_variant in NODAL_VARIANTS:
            return geo.cell_name + LAGRANGE2
    return None


def space_refusal(solver: StepState) -> str | None:
    """Why ``solver``'s space and mesh do not take the compiled passes (None where they do,
    exactly where :func:`compiled_space` gives a cell type)."""
    if compiled_space(solver) is not None:
        return None
    V = solver.V
    geo = solver.particles.locator.geometry
    element = V.element.basix_element
    if not AVAILABLE:
        return "numba is not installed"
    if V.dofmap.index_map_bs != solver.particles.gdim:
        return f"the space has {V.dofmap.index_map_bs} components; the compiled passes take a vector space of the mesh's dimension"
    if geo.kernel_cell is None:
        return "the mesh's cells are not affine simplices or multilinear quadrilaterals or hexahedra (curved cells)"
    if element.family != basix.ElementFamily.P or element.discontinuous:
        return "the element is not a continuous Lagrange or Bernstein one"
    if element.degree == 2 and not (geo.affine and geo.cell_name in SIMPLICES):
        return "degree 2 takes the compiled passes on affine simplices only"
    if element.degree == 2:
        return f"the degree-2 Lagrange variant {element.lagrange_variant.name} is neither nodal nor Bernstein"
    return f"degree {element.degree}: the compiled passes take degree 1, or degree 2 on simplices"
