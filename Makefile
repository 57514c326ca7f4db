# Every target bootstraps .venv itself on a fresh machine, with the tested versions
# (constraints.txt). A companion computer needs only `pip install .` (docs/GUIDE.md).
PY ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-unit lint bench clean

PIP_INSTALL := $(VPY) -m pip install --quiet -c constraints.txt

$(STAMP): pyproject.toml constraints.txt
	test -x $(VPY) || $(PY) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	$(PIP_INSTALL) -e '.[test]'
	touch $(STAMP)

$(VENV)/.bench: $(STAMP)
	$(PIP_INSTALL) -e '.[test,bench]'
	touch $(VENV)/.bench

demo: $(STAMP)
	$(VENV)/bin/companion demo

# every test, four files at a time (pytest-xdist: the real-process flights mostly wait, so four
# share the two cores; each file's tests stay together, on free ports)
test: $(STAMP)
	$(VPY) -m pytest -q -n 4 --dist loadfile

# the unit and property tests alone (about 2 minutes on two cores)
test-unit: $(STAMP)
	$(VPY) -m pytest -q -n 2 tests/unit

# ruff (lint and format) over the tree, mypy over the core packages ([tool.mypy] in pyproject.toml)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy

bench: $(VENV)/.bench
	$(VPY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) out
