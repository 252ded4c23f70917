# pafp: `make run` runs the main job, `make test` the tests. Both install on first use.
VENV ?= .venv
# The interpreter of .venv: the distribution's CPython 3.11+ when it has venv and its headers (Debian builds
# it with PGO and LTO: the virtual bench runs 15-25 % faster than on pyenv's plain build), else python3.
PYTHON ?= $(shell for p in /usr/bin/python3 python3; do $$p -c 'import sys, sysconfig, os, ensurepip; \
  sys.exit(sys.version_info < (3, 11) or not os.path.exists(sysconfig.get_paths()["include"] + "/Python.h"))' \
  2>/dev/null && { echo $$p; break; }; done)
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pafp-installed
ARGS ?=
SHELL := /bin/bash

.PHONY: install test fuzz bench lint run clean

# The hot path is compiled with mypyc: an edit of any module listed in setup.py's COMPILED rebuilds it, one
# compiler per core (PAFP_BUILD_JOBS=N sets how many), showing the build's `pafp build:` progress lines; pip's
# whole output is in build/install.log. PAFP_PURE_PYTHON=1 make install gives the pure-Python package instead.
# --no-compile: pip writes no bytecode beside the sources, which the tests would not read (CACHED, below, puts it in
# build/pycache). The install ends by compiling the package and its dependencies into build/pycache on every core
# (compileall: about 16 s on the 2-core machine), so the first processes of a test run do not each compile the same
# modules at once (a first `make test` after the install took 5:13 against 4:39 with the cache filled).
SOURCES := $(shell sed -n 's/^ *"\([a-z0-9_/]*\.py\)",$$/\1/p' setup.py)
# The clients extra (opensourceleg, TMotorCANControl), installed without the numpy<2 and middleware pins they declare
# but do not need (pyproject.toml's note; tests/test_sdk_clients.py drives the emulator with them). Read from
# pyproject.toml when the recipe runs (the venv's Python exists by then).
CLIENTS = $$($(PY) -c 'import tomllib; print(*tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["clients"])')
PACKAGES = firmware protocol hal rtos host_tools
EXTENSIONS = find $(PACKAGES) -name '*.so' -delete; rm -f ./*__mypyc*.so; rm -rf build

$(STAMP): pyproject.toml setup.py $(SOURCES)
	@test -x $(PY) || { $(PYTHON) -m venv $(VENV) && $(PY) -m pip install -q --no-compile --upgrade pip; }
	@$(EXTENSIONS)
	@mkdir -p build
	@echo "$(PY) -m pip install -v --no-compile -e '.[dev]' > build/install.log"
	@set -o pipefail; $(PY) -m pip install -v --no-compile -e '.[dev]' 2>&1 | tee build/install.log \
	  | { grep --line-buffered '^ *pafp build:' | sed -u 's/^ *//' || true; } \
	  || { tail -n 40 build/install.log; echo "make: pip install failed, its output is in build/install.log"; exit 1; }
	@echo "$(PY) -m pip install --no-deps <pyproject's clients extra> >> build/install.log"
	@$(PY) -m pip install --no-compile --no-deps $(CLIENTS) >> build/install.log 2>&1 \
	  || { tail -n 20 build/install.log; echo "make: installing the SDK clients failed (build/install.log)"; exit 1; }
	@echo "$(PY) -m compileall -q -j 0 <the package and its dependencies> (bytecode into build/pycache)"
	@$(CACHED) $(PY) -m compileall -q -j 0 $(PACKAGES) tests conftest.py \
	  $$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])') > build/compileall.log 2>&1 \
	  || echo "make: some modules did not compile (build/compileall.log); Python compiles them when imported"
	@touch $(STAMP)

install: $(STAMP)

# The tests and benchmarks start hundreds of Python processes (the CLI, emulators, Dask workers). Each keeps the
# bytecode it compiles in build/pycache (a cache; `make install` clears it), also where the environment sets
# PYTHONDONTWRITEBYTECODE: without a cache every process compiles what it imports again (a serial run's modules with
# numpy and scipy: 4.7 s of CPU against 1.7 s on the 2-core machine), and collecting the tests takes 22 s, not 8.
CACHED = PYTHONDONTWRITEBYTECODE= PYTHONPYCACHEPREFIX=$(CURDIR)/build/pycache

# The files that hold tests paced by the wall clock (conftest.py's REALTIME): their run collects only those.
REALTIME_FILES = $$($(PY) -c 'import conftest; print(*(f"tests/{name}" for name in conftest.REALTIME))')

# One OpenBLAS thread per process unless the environment sets OPENBLAS_NUM_THREADS: two workers on two cores, each
# with OpenBLAS's two threads that spin while they wait, spent more CPU than they saved (measured at idle on the 2-core
# machine: the first group below took 278 s with two threads, 242 s with one; the fit tests the most).
BLAS = OPENBLAS_NUM_THREADS=$${OPENBLAS_NUM_THREADS:-1}

# Two runs at once. The tests paced by the wall clock (conftest.py's REALTIME, one test at a time: a second process
# each, about one core) run at the normal priority; the rest run under `nice -n 10` on two worker processes
# (pytest-xdist), dealt whole files in conftest.py's order (FIRST: the longest first), and take what the first leaves
# of the two cores. The first's output is printed when both are done (build/test-realtime.log).
test: $(STAMP)
	@mkdir -p build
	@echo "$(PY) -m pytest -q -m realtime <conftest.REALTIME's files> > build/test-realtime.log &"
	@$(CACHED) $(BLAS) $(PY) -m pytest -q -p no:cacheprovider -m realtime $(REALTIME_FILES) \
	  > build/test-realtime.log 2>&1 & realtime=$$!; \
	echo "nice -n 10 $(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder -m 'not realtime'"; \
	$(CACHED) $(BLAS) nice -n 10 $(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder -m "not realtime" \
	  --ignore=tests/benchmarks; rest=$$?; \
	wait $$realtime; paced=$$?; \
	echo "the tests paced by the wall clock (-m realtime):"; cat build/test-realtime.log; \
	exit $$(( rest || paced ))

# The property tests under the exploring Hypothesis profile (tests/conftest.py): random seeds, more examples.
fuzz: $(STAMP)
	$(PY) -m pytest -q --hypothesis-profile=fuzz $(shell grep -l hypothesis tests/test_*.py)

bench: $(STAMP)
	@mkdir -p runs/bench
	$(CACHED) $(PY) -m pytest -q tests/benchmarks --benchmark-only --benchmark-json=runs/bench/benchmarks.json

lint: $(STAMP)
	$(VENV)/bin/ruff check .

run: $(STAMP)
	$(VENV)/bin/pafp run $(ARGS)

clean:
	@$(EXTENSIONS)
	rm -rf $(VENV) *.egg-info runs
