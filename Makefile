# Developer entry points. `make venv` is idempotent: it (re)installs only when
# requirements.txt, setup.py, setup.cfg or package.xml changed since the last install.
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c

VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.hexapod_vibration.installed
BASE_PYTHON ?= $(shell command -v python3.11 || command -v python3)

.PHONY: venv compiled test check lint demo bench soak clean

venv: $(STAMP)

$(PY):
	$(BASE_PYTHON) -m venv $(VENV)

$(STAMP): requirements.txt setup.py setup.cfg package.xml | $(PY)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	$(PY) -m pip install --disable-pip-version-check -q -e .
	cd / && $(CURDIR)/$(PY) -c 'import hexapod_vibration'
	test -x $(VENV)/bin/pph_recorder
	touch $@

# The package's bytecode, compiled before the tests: where PYTHONDONTWRITEBYTECODE is set
# (this machine, some CI images) every node process a test starts would compile it again.
compiled: venv
	$(PY) -m compileall -q hexapod_vibration > /dev/null

# Each run picks its own base ROS_DOMAIN_ID (test/conftest.py adds a per-test offset), so
# concurrent runs on one machine do not see each other's nodes; the two pytest-xdist
# workers (-n 2, one per core) take disjoint domains.
test: compiled
	HEXAPOD_TEST_DOMAIN_BASE=$${HEXAPOD_TEST_DOMAIN_BASE:-$$((20 + RANDOM % 181))} \
	  $(PY) -m pytest -q -n 2 --dist worksteal test

# The fast tier (a developer's inner loop): the tests marked unit by test/conftest.py, no
# ROS graph and no long scenario run. `make test` (and CI) runs every tier.
check: compiled
	$(PY) -m pytest -q -n 2 --dist worksteal -m unit test

lint: venv
	$(VENV)/bin/ruff check .

# A new run replaces out/demo; the run before it is kept as out/demo.previous (the
# experiment itself never overwrites a bag).
demo: venv
	if [ -d out/demo ]; then rm -rf out/demo.previous && mv out/demo out/demo.previous; fi
	$(VENV)/bin/experiment --demo --out out/demo

bench: venv
	$(VENV)/bin/hexapod_bench --out bench

# Not part of `make test`: SOAK_DURATION simulated seconds of lockstep (default one hour)
# with a drifting shaker; RSS of every process, divergence and warnings into out/soak
# (soak.json, rss.csv). SOAK_SCENARIO: any scenario (e.g. one with tracking).
SOAK_SCENARIO ?= soak_drift
SOAK_DURATION ?= 3600
soak: venv
	$(VENV)/bin/soak --scenario $(SOAK_SCENARIO) --duration $(SOAK_DURATION) --out out/soak

clean:
	rm -rf build install log out .pytest_cache .ruff_cache *.egg-info
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +
