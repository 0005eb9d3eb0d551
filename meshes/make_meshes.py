"""Regenerate the gmsh meshes shipped in this folder (needs the gmsh Python module).

    python meshes/make_meshes.py

- plate_with_hole.msh: unit square with a hole of radius 0.2 at (0.5, 0.5), triangles, h = 0.06
  (physical groups: 1 = plate; facets 1 = outer boundary, 2 = hole)
- square_quads.msh: unit square, unstructured (recombined) quadrilaterals, h = 0.1
- unit_square_tri.msh: unit square, unstructured triangles, h = 0.05 (two-disk demo)
- cube_tets.msh: unit cube, unstructured tetrahedra, h = 0.25
"""

from pathlib import Path

import gmsh

here = Path(__file__).parent


def plate_with_hole(h=0.06):
    gmsh.model.add("plate_with_hole")
    sq = gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
    hole = gmsh.model.occ.addDisk(0.5, 0.5, 0, 0.2, 0.2)
    out, _ = gmsh.model.occ.cut([(2, sq)], [(2, hole)])
    gmsh.model.occ.synchronize()
    surf = out[0][1]
    gmsh.model.addPhysicalGroup(2, [surf], 1, "plate")
    curves = [c[1] for c in gmsh.model.getBoundary([(2, surf)], oriented=False)]
    outer, inner = [], []
    for c in curves:
        x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, c)
        (inner if x0 > 0.2 and x1 < 0.8 and y0 > 0.2 and y1 < 0.8 else outer).append(c)
    gmsh.model.addPhysicalGroup(1, outer, 1, "outer")
    gmsh.model.addPhysicalGroup(1, inner, 2, "hole")
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", h)
    gmsh.model.mesh.generate(2)


def _unit_square(name, h, quads):
    gmsh.model.add(name)
    s = gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.addPhysicalGroup(2, [s], 1, "square")
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", h)
    if quads:
        gmsh.option.setNumber("Mesh.Algorithm", 8)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(2)


def square_quads(h=0.1):
    _unit_square("square_quads", h, quads=True)


def unit_square_tri(h=0.05):
    _unit_square("unit_square_tri", h, quads=False)


def cube_tets(h=0.25):
    gmsh.model.add("cube_tets")
    v = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.addPhysicalGroup(3, [v], 1, "cube")
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", h)
    gmsh.model.mesh.generate(3)


if __name__ == "__main__":
    for make in (plate_with_hole, square_quads, unit_square_tri, cube_tets):
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.RandomSeed", 0)
        make()
        gmsh.write(str(here / f"{make.__name__}.msh"))
        gmsh.finalize()
        print("wrote", here / f"{make.__name__}.msh")
