# Every target sets itself up: `make demo` and `make test` create .venv (pinned versions) if missing.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
MPIEXEC := $(VENV)/bin/mpiexec
STAMP  := $(VENV)/.installed
# numba compiles the solver kernels on first use (~20 s) and caches them in .numba-cache/<digest of the
# kernel sources> (or under NUMBA_CACHE_DIR; solvers/kernel_cache.py, stdlib only): compile them here,
# once. The stamp lives in the digest's directory, so a changed kernel source (a new digest) or a
# deleted cache re-warms.
WARM   := $(shell $(PYTHON) solvers/kernel_cache.py)/.immerse-kernels-warm
# One thread per MPI rank so ranks do not oversubscribe the cores.
export NUMBA_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export OPENBLAS_NUM_THREADS ?= 1
# Python keeps our modules' compiled bytecode (__pycache__, ignored by git) even where the
# environment says not to write it: every job starts 3-5 Python processes that import ~40 of them,
# recompiled from source at each start otherwise (a 1-step Sod job, medians of 10: the ALE rank's
# CPU 1.10 -> 0.76 s, the coupler's 0.34 -> 0.27 s, the launcher's 0.45 -> 0.34 s)
unexport PYTHONDONTWRITEBYTECODE

.PHONY: venv demo test test-fast test-serial test-mpi bench clean

# The pinned packages are installed by uv (itself pinned, from PyPI): parallel downloads and no
# byte-compiling at install (Python compiles a module on its first import), 11 s on a fresh machine
# here against pip's 65 s. Where uv cannot be had, pip installs the same pins.
UV := uv==0.13.9

$(STAMP): requirements.txt pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	{ $(PY) -m pip install -q $(UV) && $(VENV)/bin/uv pip install -q --python $(PY) -r requirements.txt; } \
	    || { echo "make: installing with uv failed; installing with pip" >&2; \
	         $(PY) -m pip install -q --upgrade pip && $(PY) -m pip install -q -r requirements.txt; }
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	touch $(STAMP)

$(WARM): $(STAMP)
	$(PY) -m orchestrator.warmup
	mkdir -p $(dir $(WARM))
	touch $(WARM)

venv: $(STAMP) $(WARM)

# the main job: an elastic plate in a shock tube, the body coupled to the gas (about 10 s), then its
# pictures: every field at the end, the pressure with the plate over it at every output step, and the
# plate's tip against time beside its reference (OUT/plots/)
demo: venv
	$(VENV)/bin/immerse run cases/plate_in_shock_2d --out cases/plate_in_shock_2d/out --replace
	$(VENV)/bin/immerse view cases/plate_in_shock_2d/out
	$(VENV)/bin/immerse view cases/plate_in_shock_2d/out --field pressure --step all --movie
	$(VENV)/bin/immerse plot cases/plate_in_shock_2d/out tip --csv

test: test-serial test-mpi

# the serial suite on one pytest-xdist worker per core (`-n auto`; tests/conftest.py keeps a module's
# shared fixture and the Slurm tests on one worker): most tests run solver jobs of 2-5 processes, so
# two workers on 2 cores oversubscribe, and the launcher lets MPICH's waiting ranks sleep then; our
# own waits sleep after their first polls (adapters/protocol.py SPIN_ENV: every job beside another)
test-serial: venv
	IMMERSE_WAIT_SPIN_S=0 $(PY) -m pytest -q -p no:cacheprovider -n auto --durations=25 tests

# for iteration: the suite without the tests marked `slow` (the long validations; every test module
# keeps tests that run), on the same workers
test-fast: venv
	IMMERSE_WAIT_SPIN_S=0 $(PY) -m pytest -q -p no:cacheprovider -n auto -m "not slow" --durations=15 tests

test-mpi: venv
	$(MPIEXEC) -n 2 $(PY) -m pytest -q -p no:cacheprovider -m mpi tests

bench: venv
	$(VENV)/bin/immerse bench lagrange

clean:
	rm -rf $(VENV) .pytest_cache .numba-cache
