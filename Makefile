# Two commands set everything up on a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test check lint types architecture bench docs clean servers servers-installed fleet-demo

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e '.[test,docs,cluster]'
	$(PY) -m shm_service.warmup  # compile the filter's kernels now: the first demo shows estimates at once
	touch $(STAMP)

# A bounded demo (30 simulated minutes at 4x real time: 7.5 min) of the service and its dashboard
# on the virtual rig, in a fresh var/demo/ (the previous run moves to var/demo.previous/). It says
# what happens when; Ctrl-C stops it. Options: make demo DEMO_ARGS="--duration 1200 --speed max".
DEMO_ARGS ?=
demo: $(STAMP)
	$(PY) -m shm_service.warmup  # at once when cached; after a pull that changed the kernels, compiles them first
	$(VENV)/bin/shm demo $(DEMO_ARGS)

# The lint and the types ([tool.ruff], [tool.mypy] in pyproject.toml: strict on contract, estimator, analytics,
# web and tools; every function body of shm_service checked).
lint: $(STAMP)
	$(VENV)/bin/ruff check .

types: $(STAMP)
	$(VENV)/bin/mypy

# No import cycle of any kind (modules or sibling packages, lazy and type-only imports included) and
# docs/development/tree.md equal to the folders (tools/architecture.py; --write regenerates the page).
architecture: $(STAMP)
	$(PY) tools/architecture.py --check

# The quick tier (under 2 minutes on 2 cores): lint, types, the architecture and the unit tests; no browser, no service
# processes, no long physics runs (the markers of tests/conftest.py).
check: lint types architecture servers-installed
	$(PY) -m pytest -q -n auto --dist loadgroup --no-loadscope-reorder -m "not slow and not e2e and not browser"

# Everything: lint, types, the architecture and the whole suite. One worker per core, single tests handed out as workers
# free up (--dist loadgroup): the tests sharing a module fixture (the quick study, a served service)
# go to one worker so it runs once; tests/conftest.py puts the long tiers first.
# TEST_WORKERS: the xdist workers (default: one per core); the browser and service tests mostly wait
# on paced replays, so a worker more than the cores may pay off: make test TEST_WORKERS=3.
TEST_WORKERS ?= auto
test: lint types architecture servers-installed
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup --no-loadscope-reorder

# PostgreSQL and Mosquitto (Debian's packages) when missing: the tests of a fleet start throwaway
# servers of their own (shm_service/devservers.py); apt-get update once, then the install (as root).
servers-installed:
	@bash .ci/install-servers

# A throwaway PostgreSQL and Mosquitto on free loopback ports for a local demo against real servers;
# it prints their URLs. Ctrl-C stops both, their data go with them.
servers: $(STAMP) servers-installed
	$(PY) -m shm_service.devservers

# A demo of two nodes: both servers, two `shm serve --node` processes sharing four mqtt structures
# through leases, and a gateway publishing the virtual rig at real time; it prints the URLs.
# Ctrl-C stops everything (nodes first, then the servers); kill -9 a node to watch the failover.
fleet-demo: $(STAMP) servers-installed
	$(PY) -m shm_service.devservers --two-nodes

bench: $(STAMP)
	$(PY) -m benchmarks

# The documentation site into site/, offline; the reference and validation pages are generated (docs_reference.py).
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

# Everything the setup and the runs made: the venv, build files and var/ (the demo's and serve's data).
clean:
	rm -rf $(VENV) build *.egg-info var site
