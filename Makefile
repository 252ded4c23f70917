# pafp: `make run` runs the main job, `make test` the tests. Both install on first use.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pafp-installed
ARGS ?=

.PHONY: install test bench lint run clean

# The hot path is compiled with mypyc (setup.py): any edit under firmware/, hal/ or rtos/ rebuilds it.
# PAFP_PURE_PYTHON=1 make install gives the pure-Python package instead.
SOURCES := $(shell find firmware hal rtos -name '*.py' 2>/dev/null)
EXTENSIONS = find firmware hal rtos host_tools -name '*.so' -delete; rm -f ./*__mypyc*.so; rm -rf build

$(STAMP): pyproject.toml setup.py $(SOURCES)
	@test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	@$(EXTENSIONS)
	$(PY) -m pip install -q -e '.[dev]'
	@touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q --ignore=tests/benchmarks

bench: $(STAMP)
	@mkdir -p runs/bench
	$(PY) -m pytest -q tests/benchmarks --benchmark-only --benchmark-json=runs/bench/benchmarks.json

lint: $(STAMP)
	$(VENV)/bin/ruff check .

run: $(STAMP)
	$(VENV)/bin/pafp run $(ARGS)

clean:
	@$(EXTENSIONS)
	rm -rf $(VENV) *.egg-info runs
