# Set-up is part of every target: .venv (pinned) -> msg_defs built into it -> package installed.
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
# pip on this machine warns about absent local mirrors; hide that noise, keep real errors.
PIP_QUIET := 2>&1 | { grep -v '^WARNING: Location' || true; }
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# The tests start hundreds of Python processes (nodes, CLI commands, workers): let them reuse the
# package's compiled modules (__pycache__, git-ignored) even where the shell says not to write them.
unexport PYTHONDONTWRITEBYTECODE
PKG_SOURCES := $(shell find rcbht_introspection config launch resource scripts -type f -not -name '*.pyc' 2>/dev/null) setup.py setup.cfg package.xml
MSG_SOURCES := $(wildcard msg_defs/msg/*.msg msg_defs/srv/*.srv msg_defs/action/*.action msg_defs/CMakeLists.txt msg_defs/package.xml)

.PHONY: setup demo test bench soak lint clean

# msg_defs' build and MiniRocket's compilation do not wait on each other: two jobs.
setup:
	@$(MAKE) --no-print-directory -j2 $(VENV)/.pkg-stamp $(VENV)/.numba-stamp

# requirements-peers.txt (the `peers` extra: hmmlearn) is resolved together with the rest,
# so its pins and requirements.txt's cannot disagree.
$(VENV)/.deps-stamp: requirements.txt requirements-ros.txt requirements-peers.txt
	@for tool in cmake cc; do command -v $$tool > /dev/null || { 	  echo "make: $$tool not found; building msg_defs needs CMake and a C compiler" 	    "(Debian: apt install cmake build-essential)" >&2; exit 1; }; done
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check --no-compile -r requirements.txt \
	  -r requirements-peers.txt $(PIP_QUIET)
	touch $@

$(VENV)/.msgs-stamp: $(VENV)/.deps-stamp $(MSG_SOURCES)
	@if [ -f msg_defs/CMakeLists.txt ]; then \
	  V=$$(cd $(VENV) && pwd); \
	  mkdir -p build; \
	  echo "building msg_defs (rcbht_interfaces) into $(VENV); log: build/msg_defs.log"; \
	  cmake -S msg_defs -B build/msg_defs -DCMAKE_PREFIX_PATH=$$V -DCMAKE_INSTALL_PREFIX=$$V \
	    -DPython3_EXECUTABLE=$$V/bin/python -DBUILD_TESTING=OFF > build/msg_defs.log 2>&1 || { cat build/msg_defs.log; exit 1; }; \
	  cmake --build build/msg_defs -j2 >> build/msg_defs.log 2>&1 || { cat build/msg_defs.log; exit 1; }; \
	  cmake --install build/msg_defs >> build/msg_defs.log 2>&1 || { cat build/msg_defs.log; exit 1; }; \
	fi
	touch $@

$(VENV)/.pkg-stamp: $(VENV)/.msgs-stamp $(PKG_SOURCES)
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation --force-reinstall . $(PIP_QUIET)
	touch $@

# aeon's MiniRocket kernels (the verifier's shape head, the peer columns) are numba functions
# compiled on first use and cached in the venv: compile them once here (about 30 s), not in
# whichever command or test first scores the peers (twice when two processes race for it).
$(VENV)/.numba-stamp: $(VENV)/.deps-stamp
	$(PY) -c "import numpy as np; from aeon.transformations.collection.convolution_based import MiniRocket; MiniRocket(random_state=0).fit_transform(np.random.default_rng(0).normal(size=(4, 6, 20)))"
	touch $@

demo: setup
	$(VENV)/bin/rcbht demo --out demo_out

# The test that leases every free ROS domain runs first, alone. Then two suites side by side, each
# on two pytest-xdist workers (whole files per worker): the ROS tests, which mostly wait on node
# processes and DDS, and the rest. The ROS suite's report is printed when both have ended. A
# background job of a script ignores Ctrl-C unless told otherwise (trap - INT): Ctrl-C then ends
# both, make waits. Imported modules are compiled on first use (pip --no-compile).
XDIST := -n 2 --dist loadfile
test: lint
	mkdir -p build
	$(PY) -m pytest -q -m leases_domains
	( trap - INT; exec $(PY) -m pytest -q -m ros $(XDIST) --durations=15 ) \
	  > build/pytest-ros.log 2>&1 & ros=$$!; \
	trap 'wait $$ros; exit 130' INT; \
	core=0; $(PY) -m pytest -q -m "not (ros or leases_domains)" $(XDIST) --durations=10 || core=$$?; \
	ros_rc=0; wait $$ros || ros_rc=$$?; \
	echo "--- ROS tests (build/pytest-ros.log) ---"; cat build/pytest-ros.log; \
	exit $$(( core || ros_rc ))

bench: setup
	$(PY) -m rcbht_introspection.bench --out bench_out

# one hour of 2 x 1 kHz wrench through both nodes (RCBHT_SOAK_SECONDS shortens it): bench_out/soak.json
soak: setup
	$(PY) -m rcbht_introspection.bench --only soak --out bench_out

lint: setup
	$(VENV)/bin/ruff check rcbht_introspection test launch
	$(VENV)/bin/ruff format --check rcbht_introspection test launch
	$(VENV)/bin/mypy

clean:
	rm -rf $(VENV) build *.egg-info
