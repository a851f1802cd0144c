# Two entry points for a fresh clone: `make demo` and `make test`. Both create or reuse .venv, install the pinned
# requirements and this package, and are safe to re-run.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
REQUIREMENTS := $(VENV)/.requirements-installed
STAMP := $(VENV)/.crane_stiffness-installed
SOURCES := $(shell find crane_stiffness config launch nodes_bin foxglove rosdep -type f \( -name '*.py' -o -name '*.yaml' -o -path 'nodes_bin/*' -o -path '*/web/*' -o -name '*.json' -o -name '*.xml' \) 2>/dev/null) \
           setup.py setup.cfg package.xml resource/crane_stiffness

# DDS stays on this machine: loopback discovery only, and a domain id of its own for every run.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= $(shell $(PYTHON) -c 'import random; print(random.randint(1, 100))')
# The venv is the ament prefix that holds rclpy and the message packages (first; prefixes a sourced ROS setup file
# put there, e.g. the one of the genuine ros2 command line, stay behind it).
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH))
export RMW_IMPLEMENTATION := rmw_fastrtps_cpp
export MPLBACKEND := Agg
export PYTHONDONTWRITEBYTECODE := 1
# Test processes `make test` runs side by side: one more than the cores, since each spends much of its time waiting
# for node processes and DDS (on two cores beside a busy process three took 9.5 min where two took 12.5-13.5);
# at most 8, as the tests' DDS domains are shared out among them (`make test TEST_PROCESSES=1`: one, in collection
# order).
TEST_PROCESSES ?= $(shell n=$$(nproc); echo $$(( n + 1 < 8 ? n + 1 : 8 )))

.PHONY: demo test bench install clean

install: $(STAMP)

# The pinned requirements, with uv (pinned here): it fetches and unpacks the wheels in parallel, ~10 s where pip took
# 50 s on the 2-core machine. --system-certs: the machine's own certificate store, as pip uses it (a lab network's
# proxy signs with a CA the machine trusts, not uv's bundled roots). --link-mode copy: the venv owns its files.
$(REQUIREMENTS): requirements.txt requirements-test.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check uv==0.13.9
	$(BIN)/python -m uv pip install --quiet --system-certs --link-mode copy --python $(BIN)/python \
		-r requirements-test.txt
	@touch $@

$(STAMP): $(REQUIREMENTS) $(SOURCES)
	@# setuptools reuses build/lib: a module moved or deleted in the tree would stay installed from it.
	rm -rf build/lib build/bdist.* crane_stiffness.egg-info
	@# As a wheel, with the venv's pinned setuptools and wheel: the console script and the node executables go to
	@# .venv/bin with any pip (pip < 23.1 would otherwise run the legacy `setup.py install`, which follows setup.cfg's
	@# colcon layout and puts them in .venv/lib/crane_stiffness). --no-compile: byte-compiled below with the rest.
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-compile --use-pep517 \
		--no-build-isolation --no-deps --force-reinstall .
	@# Compile the model's numba kernels into their cache beside the installed modules (numba keys it by the
	@# files' contents): no node or CLI call compiles them at run time; colcon build copies this cache into its
	@# install tree (setup.py). The kernel compile is one thread: meanwhile the other core byte-compiles the
	@# installed modules, which every process started from the venv then loads instead of compiling them in memory
	@# (PYTHONDONTWRITEBYTECODE=1 above). The kernel compile writes the .pyc of what it imports itself, so it does not
	@# wait for them; both write each file atomically. compileall's status is ignored like pip's own compile step
	@# ignores it: a few packages ship files for other Python versions that do not compile.
	@# The source tree gets a copy of the cache too: scripts/demo.py and the tests import the package from it (the
	@# demo's summary solves the model in its own process). A cache of an earlier install goes first: numba checks
	@# each kernel's cache against its own file only, and a kernel compiled into another would stay stale.
	find $(VENV)/lib/python*/site-packages/crane_stiffness crane_stiffness -name '*.nb[ic]' -delete
	($(BIN)/python -m compileall -q $(VENV)/lib >/dev/null || true) & \
	(cd $(VENV) && PYTHONDONTWRITEBYTECODE= bin/python -m crane_stiffness.model.kernel_cache --copy-to $(CURDIR)) \
		&& wait $$!
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python scripts/demo.py

test: $(REQUIREMENTS)
	$(BIN)/ruff check crane_stiffness test benchmarks scripts launch setup.py
	@# Type checks of the package (mypy.ini; it reads the source tree), beside the install and its kernel compile:
	@# ~40 s less from a fresh clone. Its cache (.mypy_cache/) makes a re-run take under a second.
	@$(BIN)/mypy & mypy=$$!; $(MAKE) --no-print-directory install; installed=$$?; wait $$mypy && exit $$installed
	@# TEST_PROCESSES test processes (pytest-xdist), each taking tests as it finishes one (worksteal: the few long
	@# rig tests do not queue behind each other); conftest.py gives each its own share of the DDS domains.
	$(BIN)/python -m pytest -q -p no:cacheprovider -n $(TEST_PROCESSES) --dist worksteal --durations=15 test

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf build install log out
