# fempm: `make demo` runs the main demo, `make test` runs the tests (serial, then MPI on 2 ranks),
# `make test-all` also the slow ones (the long studies and demos, the full test matrices), `make docs`
# the site (docs/_build/html/index.html).
# Both create the virtual environment .venv when it is missing.
VENV    ?= .venv
PY      := $(VENV)/bin/python
MPIEXEC := $(VENV)/bin/mpiexec
NPROCS  ?= 2

.PHONY: venv demo test test-all docs study quick bench clean

venv:
	@bash scripts/bootstrap

demo: venv
	$(PY) demos/two_disks.py

test: venv
	bash scripts/run-tests

test-all: venv
	FEMPM_TEST_ALL=1 bash scripts/run-tests

# the site: the docs pages, the API reference from the docstrings, the demos, into docs/_build/html
docs: venv
	$(PY) -m sphinx -W --keep-going -b html docs docs/_build/html

study: venv
	$(PY) -m fempm study mapping

# the quick version of every study output and benchmark table, into output/quick
quick: venv
	bash scripts/regenerate-quick

bench: venv
	$(PY) benchmarks/bench_mapping.py
	$(PY) benchmarks/bench_step.py

clean:
	rm -rf $(VENV) output .pytest_cache
