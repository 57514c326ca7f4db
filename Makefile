# Every target bootstraps .venv itself on a fresh machine.
PY ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	test -x $(VPY) || $(PY) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	$(VPY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

$(VENV)/.bench: $(STAMP)
	$(VPY) -m pip install --quiet -e '.[test,bench]'
	touch $(VENV)/.bench

demo: $(STAMP)
	$(VENV)/bin/companion demo

test: $(STAMP)
	$(VPY) -m pytest -q

bench: $(VENV)/.bench
	$(VPY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) out
