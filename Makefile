# Every target bootstraps .venv itself on a fresh machine, with the tested versions
# (constraints.txt). A companion computer needs only `pip install .` (docs/GUIDE.md).
PY ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

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

test: $(STAMP)
	$(VPY) -m pytest -q

bench: $(VENV)/.bench
	$(VPY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) out
