"""The KSP defaults of the kept consistent mass systems (:class:`fempm.stepping.mass_systems.ConsistentSystems`;
the options prefix of the step overrides them), each with what chose it."""

from __future__ import annotations

from dolfinx.mesh import CellType

__all__ = ["KSP_OPTIONS", "KSP_OPTIONS_PARALLEL", "SIGNED_OPTIONS", "SIMPLEX_OPTIONS", "ksp_options"]

#: KSP defaults of the kept systems on one rank (the options prefix overrides them): CG with
#: incomplete Cholesky, 5-10 iterations where Jacobi takes 50-60 (P1/Q1, 4 particles per cell).
#: CG stops on the true residual, :math:`\|b - m u\|_2 \le` rtol :math:`\|b\|_2` (unless
#: the options prefix sets ``ksp_norm_type``): with a warm start, the preconditioned norm needs
#: the preconditioner applied to ``b`` once more per solve (about 2.5 ms at 1e6 particles), the
#: true one half an iteration more on average; a step is 5 % faster (median of 3-step batches
#: alternating in one process)
KSP_OPTIONS = {"ksp_type": "cg", "pc_type": "bjacobi", "sub_pc_type": "icc"}
#: on several ranks: incomplete Cholesky on each rank's rows and one layer of their neighbours
#: (restricted additive Schwarz, overlap 1). Block Jacobi drops the couplings across the
#: partition and takes 2-3x the iterations at the 1e-13 tolerance (20 instead of 7-11 on two
#: ranks, 1e6 particles on triangles); the restricted Schwarz preconditioner is not symmetric,
#: so GCR (minimal residual, any preconditioner) replaces CG. A step is 17 % faster.
KSP_OPTIONS_PARALLEL = {"ksp_type": "gcr", "pc_type": "asm", "sub_pc_type": "icc"}
#: added on simplices: incomplete Cholesky with one level of fill. At 1e6 particles on gmsh
#: triangles the solves take 7-8 iterations instead of 11-12 and a step is 15-25 % faster on 1
#: and 2 ranks (the set-up, once a step, costs more); on quadrilaterals the iterations do not
#: drop (8-9) and the step is 4 % slower, so they keep ICC(0). With particle domains on
#: triangles too, on the pairs they couple (:mod:`fempm.stepping.mass_sparsity`): CPDI1 at 1e5
#: 2.54 -> 2.28x the consistent point step (``benchmarks/bench_configurations.py --configs
#: cons-cpdi1``); not on tetrahedra, whose domains' rows hold 100-1000 entries (CPDI1 at 1e4:
#: 65 against 112 ms a step with one level, exact uGIMP 156 against 166 ms)
SIMPLEX_OPTIONS = {"sub_pc_factor_levels": 1}
#: a basis with negative values (P2 Lagrange), on any number of ranks: CG with the diagonal.
#: Incomplete Cholesky of its mass breaks down (an indefinite factor: CG stops at once; on two
#: ranks GCR with restricted Schwarz ran 20000 iterations without reaching the tolerance)
SIGNED_OPTIONS = {"ksp_type": "cg", "pc_type": "jacobi"}


def ksp_options(ranks: int, cell_type: CellType, nonnegative: bool, domains: bool) -> dict:
    """The KSP options of the systems on ``ranks`` ranks of cells ``cell_type``, of a basis that
    is ``nonnegative`` (else :data:`SIGNED_OPTIONS`), of point particles or particle ``domains``."""
    if not nonnegative:
        return dict(SIGNED_OPTIONS)
    options = dict(KSP_OPTIONS if ranks == 1 else KSP_OPTIONS_PARALLEL)
    if cell_type == CellType.triangle or (cell_type == CellType.tetrahedron and not domains):
        options.update(SIMPLEX_OPTIONS)
    return options
