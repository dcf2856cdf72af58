# Every target sets itself up: `make demo` and `make test` create .venv (pinned versions) if missing.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
MPIEXEC := $(VENV)/bin/mpiexec
STAMP  := $(VENV)/.installed
# One thread per MPI rank so ranks do not oversubscribe the cores.
export NUMBA_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: venv demo test test-serial test-mpi bench clean

$(STAMP): requirements.txt pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.txt
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	touch $(STAMP)

venv: $(STAMP)

demo: venv
	$(VENV)/bin/immerse run cases/taylor_bar --out cases/taylor_bar/out --replace
	$(VENV)/bin/immerse view cases/taylor_bar/out

test: test-serial test-mpi

test-serial: venv
	$(PY) -m pytest -q -p no:cacheprovider tests

test-mpi: venv
	$(MPIEXEC) -n 2 $(PY) -m pytest -q -p no:cacheprovider -m mpi tests

bench: venv
	$(VENV)/bin/immerse bench lagrange

clean:
	rm -rf $(VENV) .pytest_cache
