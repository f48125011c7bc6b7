# Two commands for a fresh machine: `make demo` and `make test`. Both create .venv when it is missing.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
PYTEST_ARGS ?=
# pytest's workers (pytest-xdist) in `make test`: two for the two cores of the target machine; 0 runs serially
PYTEST_JOBS ?= 2

.PHONY: demo test lint bench clean chromium compile

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,bench,dask,import]'
	touch $(STAMP)

# The swarm as processes with its dashboard (http://localhost:8080), at twice real time (a docking takes about
# a minute), a new seed after each docking, until Ctrl-C. `swarm demo` is the in-process tour (no browser).
# (Ctrl-C mid-run exits 130, README "Exit status": the stop asked for, which make would call an error)
demo: compile
	$(VENV)/bin/swarm launch docking --clock scaled:2 --repeat || test $$? -eq 130

# numba's kernels compiled into its cache before the first run, the independent chains in parallel processes
# (swarm/cli/compile.py): ~2 min on two cores for a fresh checkout instead of ~4 min paid inside the first
# tests and processes; a few seconds when cached. Only a speed-up: a chain that fails is named and the
# tests (or the demo) run anyway, compiling what is missing themselves (and failing where it is broken)
compile: $(STAMP)
	-$(VENV)/bin/swarm compile

# ruff, then the import layers of docs/architecture.md (.importlinter)
lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(VENV)/bin/lint-imports --no-cache

# The dashboard's browser tests drive Debian's chromium through playwright (no browser download). Install it
# when missing (apt, as root or through sudo); if that is impossible, those tests skip and say why.
chromium:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" -eq 0 ]; then SUDO=; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo -n"; \
	  else echo "make: chromium missing and neither root nor sudo: browser tests will skip" >&2; exit 0; fi; \
	  if ! command -v apt-get >/dev/null 2>&1; then \
	    echo "make: chromium missing and no apt-get: browser tests will skip" >&2; exit 0; fi; \
	  $$SUDO apt-get update && $$SUDO apt-get install -y chromium \
	    || echo "make: could not install chromium: browser tests will skip" >&2; }

# The suite on $(PYTEST_JOBS) workers: whole files per worker (their module fixtures start once), the files that
# launch swarms and browsers handed out first; a test marked `alone` runs with nothing beside it
# (tests/xdist_turns.py). pytest exits 5 when it collects nothing: that is a failure of the suite, say so
# instead of passing.
test: lint chromium compile
	$(PY) -m pytest -n $(PYTEST_JOBS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS); rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests" >&2; exit 1; fi; exit $$rc

bench: $(STAMP)
	$(VENV)/bin/swarm bench estimator

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
