# `make test` and `make demo` set everything up on a fresh machine.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: test demo install bench clean

install: $(STAMP)

# torch first, pinned: it is the CPU wheel on local disk (anything else downloads gigabytes).
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

# The venv's console scripts (moosdb, pAntler, ...) must be on PATH for tests that launch them.
export PATH := $(abspath $(VENV))/bin:$(PATH)

# -rs: the summary names each skipped test and why (e.g. needs ../shared/missions-corpus).
test: $(STAMP)
	$(PY) -m pytest -rs

demo: $(STAMP)
	$(PY) -m oilspill_moos.demo $(DEMO_ARGS)

bench: $(STAMP)
	for b in benchmarks/*.py; do $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info
