r"""Particle weights that apply a traction on a mesh boundary as the finite element's consistent
nodal load: :func:`consistent_weights`.

A particle traction :math:`\bar t_p` with a share :math:`w_p` of the loaded surface puts
:math:`f_i = \sum_p w_p N_i(x_p)\, \bar t_p` on the grid. Shares that only sum to the surface's
measure (:func:`fempm.stepping.loads.surface_areas`, :func:`fempm.boundary.surface_load`) apply
the right total force but spread it as the particles' basis values do: the particles sit inside
the cells, so part of the load reaches nodes off the surface. Where the loaded surface is a set
of facets of the mesh's own boundary (a body meshed as itself, as Cook's membrane), the finite
element method applies :math:`f_i = \int_\Gamma N_i\, ds\; \bar t`. The weights here reproduce
it: in each cell :math:`c` with loaded facets :math:`F \subset \partial c`, the weights of the
particles of :math:`c` are the least-norm solution of

.. math::
    \sum_{p \in c} w_p\, \phi_k(X_p) = \sum_{F \subset \partial c} \int_F \phi_k\, ds
    \qquad \text{for each basis function } \phi_k \text{ of } c

(:math:`X_p` the particles' reference coordinates; a Gauss rule on the facet, exact for the
element's degree on straight facets), so that the grid force is the consistent one while the
particles stay where they were seeded. Weights may be negative (a node opposite the facet gets
no load from particles that all see it). They sum to the facets' measure (the basis is a
partition of unity). A uniform traction then loads the nodes exactly as a finite element code
does, and a refinement converges as the finite element solution on the same mesh.
"""

from __future__ import annotations

import basix
import numpy as np
import numpy.typing as npt

from fempm.meshes.facets import facet_area_vectors

__all__ = ["consistent_weights"]

#: the reference cell of each cell type's facets
_FACET_CELL = {"triangle": "interval", "quadrilateral": "interval", "tetrahedron": "triangle",
               "hexahedron": "quadrilateral"}


def consistent_weights(particles, facets: npt.NDArray[np.int32], element: basix.finite_element.FiniteElement
                       ) -> npt.NDArray:
    """Each particle's weight (n,) in the consistent nodal load of a traction on the local
    boundary ``facets`` (see the module); 0 for the particles of cells without one.

    Args:
        particles: The particles, in their reference configuration (their ``cells`` and
            reference coordinates ``X``).
        facets: Local indices of facets on the mesh's boundary (one cell beside each).
        element: The scalar basix element of the nodal basis (the family, degree and variant
            of the velocity space).

    Returns:
        The weights; their sum over a cell is the measure of its loaded facets.

    Raises:
        ValueError: A facet with two cells beside it, or a loaded cell holding fewer particles
            than the element has basis functions, or particles whose basis values leave the
            system singular.

    Note:
        Not collective: each rank weighs the particles of its owned cells (a boundary facet's
        cell is owned by one rank).
    """
    mesh = particles.mesh
    tdim = mesh.topology.dim
    fdim = tdim - 1
    mesh.topology.create_connectivity(fdim, tdim)
    mesh.topology.create_connectivity(tdim, fdim)
    f2c, c2f = mesh.topology.connectivity(fdim, tdim), mesh.topology.connectivity(tdim, fdim)
    num_owned = mesh.topology.index_map(tdim).size_local
    w = np.zeros(len(particles))
    facets = np.asarray(facets, dtype=np.int32)
    if not len(facets):
        return w
    cell_type = mesh.topology.cell_type
    ref_facets = basix.topology(element.cell_type)[fdim]
    ref_x = basix.geometry(element.cell_type)
    if fdim:
        qpts, qwts = basix.make_quadrature(getattr(basix.CellType, _FACET_CELL[cell_type.name]), 2 * element.degree + 2)
        qwts = qwts / qwts.sum()
    else:  # a vertex of an interval: the value there
        qpts, qwts = np.zeros((1, 0)), np.ones(1)
    measure = np.linalg.norm(facet_area_vectors(mesh, facets), axis=1)
    order = np.argsort(particles.cells, kind="stable")
    starts = np.searchsorted(particles.cells[order], np.arange(num_owned + 1))
    rhs: dict[int, npt.NDArray] = {}
    for f, size in zip(facets, measure):
        cells = f2c.links(f)
        if len(cells) != 1:
            raise ValueError(f"facet {f} has {len(cells)} cells beside it: a consistent load needs facets of "
                             "the mesh's boundary")
        c = int(cells[0])
        if c >= num_owned:
            continue
        local = int(np.flatnonzero(c2f.links(c) == f)[0])
        verts = ref_x[ref_facets[local]]  # the reference facet's vertices (basix's order)
        # the facet's quadrature points in the cell's reference coordinates
        X = verts[0] + qpts @ (verts[1 : fdim + 1] - verts[0])
        phi = element.tabulate(0, X)[0, :, :, 0]  # (q, ndofs)
        rhs[c] = rhs.get(c, 0.0) + size * (qwts @ phi)
    for c, b in rhs.items():
        rows = order[starts[c]:starts[c + 1]]
        if len(rows) < element.dim:
            raise ValueError(f"cell {c} holds {len(rows)} particle(s) and its element {element.dim} basis functions: "
                             "a consistent load needs at least as many particles as basis functions in each "
                             "loaded cell")
        A = element.tabulate(0, particles.X[rows, :tdim])[0, :, :, 0].T  # (ndofs, np)
        if np.linalg.matrix_rank(A) < element.dim:
            raise ValueError(f"the particles of cell {c} do not determine its {element.dim} basis functions "
                             "(they lie on fewer points than a unisolvent set)")
        w[rows] = np.linalg.lstsq(A, b, rcond=None)[0]
    return w
