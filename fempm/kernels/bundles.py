"""The named bundles the compiled particle passes take their arrays in.

A pass takes a few named tuples instead of 20-40 arrays one by one: numba types a named tuple
by its class and its members' types, so a kernel reads ``basis.cells`` as it read an argument
``cells`` (the same compiled code: the kernels unpack their bundles once, before the loop),
and the callers build each bundle once where its arrays are known. The dispatch of a call costs
a few microseconds more (the members are typed one by one), a pass milliseconds
(``benchmarks/bench_configurations.py``, ``benchmarks/bench_reference.py``; docs/performance.md).

=============  ===================================================================================
bundle         members
=============  ===================================================================================
``Basis``      where the point particles sit: ``cells`` (n,), reference coordinates ``X`` (n, d),
               the cells' inverse Jacobians (or multilinear vertices) ``K``, ``cell_dofs``
``Samples``    the averaged basis of particle domains: the samples' cells ``sc`` (n, Q) and
               reference coordinates ``Y`` (n Q, d), weights ``w``, gradient weights ``gw``,
               CPDI1's ``Fw``, corner frames ``lp`` and corner ``signs``, and the space's ``K``
               and ``cell_dofs`` (:mod:`fempm.kernels.samples`)
``State``      the particle state: ``x``, ``v``, ``F``, ``volume0``, ``volume``, ``sigma``,
               ``body``, ``mass``
``Laws``       per body: compiled law code, Lame ``lam`` and ``mu``, P-wave ``modulus`` (0: none)
``GridStep``   G2P's grid fields and step: ``v_new``, ``v_old``, ``flip``, ``dt``,
               ``by_particle`` (the particles move with their own velocity)
``Star``       the cells around each vertex: ``c2v``, ``v_offsets``, ``v_cells``, ``num_cells``
``Moves``      relocation in the moving pass: the cells' origins ``x0``, ``tol``, the ``left``
               mask it writes, the vertex ``star``
``Outputs``    what G2P writes besides the state: velocity gradients ``L`` (n or 0, d, d), the
               re-mapped momenta ``mom`` (dofs or 0, ...), the state's ``sums`` (3 + d or 0)
``Forces``     P2G's external forces: constant body force ``g`` (d,), per particle ``fext``; F-bar's
               nodal pressure sums ``patch`` (dofs, 2 B; (0, 0): none; :mod:`fempm.kernels.patch`)
``Stable``     the stable time's cell sizes ``h`` (cells or 0) and given wave speeds ``c``
``Corners``    CPDI2's corners moved in the 2D moving pass: their positions ``yc`` (n, Q, 2),
               the ``moved`` ones it writes, the ``bad`` counts (inverted, not located) and the
               number of cells searched ``sample_cells``
``Groups``     multi-field contact: ``group`` per particle (or empty), column ``stride``,
               ``rigid`` per group
``Averaged``   F-bar's kinematics in the planar G2P pass (:mod:`fempm.kernels.fbar`): the nodal
               averages ``patch`` (dofs, 2 B) of the measures (which the pass computes again for
               each particle), ``by_trace`` (B,), the number of bodies B; the next force pass's
               pressure sums ``sums`` (dofs, 2 B; (0, 2): none) the pass adds to and their blocks'
               ``dirty`` marks
``Affine``     APIC/TPIC (:mod:`fempm.kernels.affine`): the particles' affine matrices ``C``
               (n, d, d), APIC's spins ``spin`` (n, 1 or 3), the dofs' coordinates ``xi``, the
               grid velocity ``v`` G2P takes the affine matrices from where a particle's
               dofs include one flagged in ``weak`` (``affine_cutoff``; (0, d): ``v_new``)
=============  ===================================================================================
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

__all__ = ["NO_AFFINE", "NO_AVERAGE", "NO_GROUPS", "Affine", "Averaged", "Basis", "Corners", "Forces", "GridStep", "Groups", "Laws", "Moves", "Outputs", "Samples", "Stable",
           "Star", "State"]

Basis = namedtuple("Basis", "cells X K cell_dofs")
Samples = namedtuple("Samples", "sc Y w gw Fw lp signs K cell_dofs")
State = namedtuple("State", "x v F volume0 volume sigma body mass")
Laws = namedtuple("Laws", "law lam mu modulus")
GridStep = namedtuple("GridStep", "v_new v_old flip dt by_particle")
Star = namedtuple("Star", "c2v v_offsets v_cells num_cells")
Moves = namedtuple("Moves", "x0 tol left star")
Outputs = namedtuple("Outputs", "L mom sums")
Forces = namedtuple("Forces", "g fext patch", defaults=(np.zeros((0, 0)),))
Stable = namedtuple("Stable", "h c")
Groups = namedtuple("Groups", "group stride rigid")
Corners = namedtuple("Corners", "yc moved bad sample_cells")
Affine = namedtuple("Affine", "C spin xi v weak")
Averaged = namedtuple("Averaged", "patch by_trace bodies sums dirty",
                      defaults=(np.zeros((0, 2)), np.zeros(0, np.uint8)))

#: one velocity field: no group per particle, no rigid group
NO_GROUPS = Groups(np.zeros(0, dtype=np.int64), 0, np.zeros(1, dtype=np.bool_))
#: no F-bar average
NO_AVERAGE = Averaged(np.zeros((0, 2)), np.zeros(0, np.bool_), 1, np.zeros((0, 2)), np.zeros(0, np.uint8))
#: no affine transfer
NO_AFFINE = Affine(np.zeros((0, 1, 1)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros(0, np.uint8))
