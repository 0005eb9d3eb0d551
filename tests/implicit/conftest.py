"""Fixtures of the implicit step's tests."""

import pytest
from petsc4py import PETSc


@pytest.fixture
def petsc_options():
    """Options set in the PETSc database for one test, removed after it."""
    opts = PETSc.Options()
    added = []

    def put(**values):
        for k, v in values.items():
            opts[k] = v
            added.append(k)

    yield put
    for k in added:
        opts.delValue(k)
