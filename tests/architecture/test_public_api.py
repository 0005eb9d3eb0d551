"""The import paths users and tools rely on keep working with the same objects, and the
top-level namespace exports the public API."""

import importlib

import pytest

import fempm

#: (module path, names) that stay importable (issue-fixed interface)
KEPT = [
    ("fempm", ["Particles", "create_particles", "project", "interpolate", "Projector"]),
    ("fempm.stepping", ["ExplicitSolver", "Solver", "StepOptions", "Loads"]),
    ("fempm.domains", ["make_domain", "box_corners", "domain_geometry", "GIMP", "CPDI1", "CPDI2", "Point"]),
    ("fempm.manufactured", ["PROBLEMS", "axis_aligned", "axis_aligned_1d", "generalized_vortex", "vibrating_bar"]),
    ("fempm.scene", ["run", "Scene"]),
    ("fempm.scenes", ["SCENES", "manufactured_scene"]),
    ("fempm.materials", ["LinearElastic", "NeoHookean", "VonMises", "DruckerPrager", "NewtonianTait"]),
    ("fempm.contact", ["Contact"]),
    ("fempm.boundary", ["fixed", "slip", "friction"]),
    ("fempm.errors", ["particle_errors"]),
    ("fempm.meshes", ["unstructured_rectangle"]),
    ("fempm.abort", ["abort_on_error"]),
]


@pytest.mark.parametrize("path, names", KEPT)
def test_kept_paths_import(path, names):
    module = importlib.import_module(path)
    missing = [n for n in names if not hasattr(module, n)]
    assert missing == []


def test_kept_paths_are_the_same_objects_as_their_homes():
    from fempm.stepping.contact import Contact
    from fempm.transfer.domains import make_domain
    from fempm.verification.manufactured import PROBLEMS

    assert importlib.import_module("fempm.contact").Contact is Contact
    assert importlib.import_module("fempm.domains").make_domain is make_domain
    assert importlib.import_module("fempm.manufactured").PROBLEMS is PROBLEMS
    assert fempm.ExplicitSolver is fempm.Solver  # the solver steps explicitly and implicitly


def test_the_top_level_namespace_exports_what_all_lists():
    assert sorted(fempm.__all__) == sorted(set(fempm.__all__))
    assert [n for n in fempm.__all__ if not hasattr(fempm, n)] == []
    for name in ("ExplicitSolver", "StepOptions", "Scene", "run", "make_domain", "Contact", "fixed", "slip",
                 "friction", "particle_errors"):
        assert name in fempm.__all__
