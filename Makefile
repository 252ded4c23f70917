# pafp: `make run` runs the main job, `make test` the tests. Both install on first use.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pafp-installed
ARGS ?=

.PHONY: install test bench lint run clean

$(STAMP): pyproject.toml
	@test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
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
	rm -rf $(VENV) build *.egg-info runs
