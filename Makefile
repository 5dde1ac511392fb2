# The two commands of the README: `make run` (the rig) and `make test` (the whole test suite).
# Both first create or refresh the venv and the colcon workspace (scripts/setup.sh; seconds when nothing
# changed). VENV selects the venv (default .venv): `VENV=/tmp/venv make test`.
SHELL := /bin/bash
.SHELLFLAGS := -o pipefail -c
.DEFAULT_GOAL := help

VENV ?= $(CURDIR)/.venv
export VENV

PYTEST_ARGS ?=

# The Pythons `make dist` builds the rimd_msgs wheel for, and `make test-dist` tests the wheels with.
DIST_PYTHONS ?= 3.11 3.12

.PHONY: help setup run test test-fast lint clean dist test-dist clean-dist

help:
	@echo "make run        set up, build and run the rig (rimd rig)"
	@echo "make test       set up, build and run the whole test suite (pytest tests, in parallel; SKIP_SLOW=1: not the slow tier)"
	@echo "make test-fast  the tests that start no process (core, recording, analyses, config): under a minute"
	@echo "make setup      only create/refresh the venv ($(VENV)) and build ros_ws"
	@echo "make lint       ruff check, lint-imports (the layer contracts) and mypy (the package's types)"
	@echo "make clean      remove ros_ws build/install/log and the set-up stamps (keeps the venv)"
	@echo "make dist       the wheels a lab installs with pip, in dist/: rimd_msgs for $(DIST_PYTHONS), rimd_sim"
	@echo "make test-dist  make dist, then install the wheels into fresh venvs outside the repository and run them"
	@echo "make clean-dist remove dist/ and .dist-build/ (the build venvs and CMake trees of make dist)"

setup:
	@bash scripts/setup.sh

run: setup
	@source ./env.sh && rimd rig

# scripts/run_tests.sh turns pytest's exit 5 (no test collected) into a failure. SKIP_SLOW=1 leaves out the tests
# marked slow (the whole identifications, the presets' table: a developer's quicker run); .ci/run runs them all.
test: setup
	@bash scripts/run_tests.sh $(if $(SKIP_SLOW),-m "not slow") $(PYTEST_ARGS)

# The inner loop: every test that starts no process (no node, CLI or worker; one that does fails here, naming the
# marker it lacks: tests/conftest.py) and is not marked slow (two whole identifications, 40 s between them; make
# test runs them). Test by test on the workers (worksteal): no test here holds a ROS domain.
test-fast: setup
	@RIMD_TEST_FAST=1 bash scripts/run_tests.sh -m "not process and not slow" --dist worksteal $(PYTEST_ARGS)

# The static checks, configured in pyproject.toml: ruff (style), import-linter (the layer contracts) and mypy (the
# package's types; its cache is .mypy_cache). All three run; any failing fails the target, naming it.
lint: setup
	@source ./env.sh || exit 1; failed=""; \
	ruff check . || failed="$$failed ruff"; \
	lint-imports --no-logo || failed="$$failed lint-imports"; \
	mypy || failed="$$failed mypy"; \
	if [ -n "$$failed" ]; then echo "make lint: failed:$$failed" >&2; exit 1; fi

clean:
	rm -rf ros_ws/build ros_ws/install ros_ws/log .stamps

# The wheels a lab installs with pip (docs/testing.md, "From your repository's CI"): the rimd_msgs wheel of each
# Python of DIST_PYTHONS and the rimd_sim wheel, in dist/. Build venvs and CMake trees are kept in .dist-build/ and
# reused while requirements.txt is unchanged; an unchanged wheel is not rebuilt (scripts/build_dist.py).
dist:
	@python3 scripts/build_dist.py $(foreach python,$(DIST_PYTHONS),--python $(python))

# The wheels from outside: for each Python, a fresh venv in a temporary directory, pip install of the wheels, then
# rimd info, a rig and its recording, a lab's tests and the CI recipe, with a clean environment; prints the times
# (scripts/test_dist.py).
test-dist: dist
	@python3 scripts/test_dist.py $(foreach python,$(DIST_PYTHONS),--python $(python))

clean-dist:
	rm -rf dist .dist-build
