# The two commands of the README: `make bench` and `make test`.
# Both create .venv if missing and install the project into it; nothing is installed by hand.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: bench test setup benchmarks paper clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $(STAMP)

setup: $(STAMP)

# A fresh default run each time (the committed results/default is replaced, not resumed;
# `contactbench run` itself resumes an interrupted run).
bench: $(STAMP)
	rm -rf results/default
	$(VENV)/bin/contactbench run default --out results/default
	$(VENV)/bin/contactbench report results/default

test: $(STAMP)
	$(PY) -m pytest -q

benchmarks: $(STAMP)
	$(PY) -m pytest --benchmark-only --benchmark-enable -q benchmarks

clean:
	rm -rf $(VENV)
