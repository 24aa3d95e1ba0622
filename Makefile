# The two commands of the README: `make bench` and `make test`.
# Both create .venv if missing and install the project into it, with its `docs` extra (the
# user's guide and its tests) and its `test` extra (hypothesis, pytest-xdist, selenium and the pinned
# ruff); nothing is installed by hand.  A change to pyproject.toml reinstalls.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: bench test test-quick lint setup setup-browser setup-peers setup-eigen benchmarks paper docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[docs,test]'
	touch $(STAMP)

setup: $(STAMP)

# A fresh default run each time, written to BENCH_OUT (build/bench/default, outside what git
# tracks, so a run never dirties the tree; `contactbench run` itself resumes an interrupted
# run).  The committed copy is regenerated with `make bench BENCH_OUT=results/default`.
BENCH_OUT ?= build/bench/default
bench: $(STAMP)
	rm -rf $(BENCH_OUT)
	$(VENV)/bin/contactbench run default --out $(BENCH_OUT)
	$(VENV)/bin/contactbench report $(BENCH_OUT)

# Debian's chromium and chromium-driver for the report's browser test (tests/harness/test_report_html.py);
# installed only where it is missing, apt-get exists and we are root -- elsewhere the test skips
# and says why.
setup-browser:
	@if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver) \
	    >/dev/null 2>&1 || echo "setup-browser: could not install chromium; the browser test will skip"; \
	else echo "setup-browser: no chromium and no root apt-get; the browser test will skip"; fi

# The `peers` extra (ContactMechanics, Tamaas, ASPHER: docs/peers.md) on top of `setup`; `make test`
# never asks for it (the peers' tests skip and say why).  ASPHER builds from its sdist (CMake, C++17,
# minutes on two cores) against Eigen 3.4: Debian's libeigen3-dev first (setup-eigen).
PEERS_STAMP := $(VENV)/.peers-stamp

$(PEERS_STAMP): pyproject.toml $(STAMP) | setup-eigen
	$(PY) -m pip install --quiet -e '.[peers]'
	touch $(PEERS_STAMP)

setup-peers: $(PEERS_STAMP)

# Debian's libeigen3-dev (Eigen 3.4) for ASPHER's build; installed only where it is missing,
# apt-get exists and we are root -- elsewhere ASPHER's CMake fetches Eigen from the internet.
setup-eigen:
	@if [ -f /usr/include/eigen3/Eigen/Core ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libeigen3-dev) \
	    >/dev/null 2>&1 || echo "setup-eigen: could not install libeigen3-dev; ASPHER's build will fetch Eigen"; \
	else echo "setup-eigen: no Eigen 3 headers and no root apt-get; ASPHER's build will fetch Eigen"; fi

# ruff with the project's configuration (pyproject.toml [tool.ruff]); any finding fails.
lint: $(STAMP)
	$(VENV)/bin/ruff check .

# The suite's pytest workers (pytest-xdist, the `test` extra; one test module a worker, so that a
# module's fixtures are built once): the CPUs this process may run on (its affinity, not the
# host's count, which xdist's "auto" reads), at most 8; with one CPU, none (0: the suite runs in
# pytest's own process, as `make test TEST_JOBS=0` asks anywhere).
TEST_JOBS ?= $(shell $(PYTHON) -c 'import os; n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(); print(min(8, n) if (n or 1) > 1 else 0)' 2>/dev/null || echo 0)
PYTEST := $(PY) -m pytest -q -rs -n $(TEST_JOBS) --dist loadscope

# The whole suite, after the linter.
test: lint setup-browser
	$(PYTEST)

# The suite without the tests marked slow (pyproject.toml's markers), after the linter.
test-quick: lint
	$(PYTEST) -m "not slow"

# The user's guide, built offline into site/ (mkdocs.yml; strict: any warning fails; the tutorial
# notebook is executed, so its page shows its outputs).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet

benchmarks: $(STAMP)
	$(PY) -m pytest --benchmark-only --benchmark-enable -q benchmarks

# The paper-scale 512^2 sweep with every registered solver (results/paper: about 40 minutes on
# 2 cores; the peers' rows need `make setup-peers`).  The folder's own command: a run that
# finds every cell recorded adds none, and the report is written again.
paper: $(STAMP)
	$(VENV)/bin/contactbench run paper-sweep --solvers all --profile high --timeout 120 --out results/paper
	$(VENV)/bin/contactbench report results/paper

clean:
	rm -rf $(VENV) site
