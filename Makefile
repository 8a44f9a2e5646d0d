# Foresight: two commands on a fresh machine with Python 3.11+.
#   make demo   set up .venv (if missing) and run the whole system with embedded defaults
#   make test   set up .venv (if missing) and run the test suite
#
# Which torch build `make setup` installs (only when .venv has no torch yet):
#   TORCH_VERSION  the pinned version (default 2.13.0)
#   TORCH_INDEX    the package index torch comes from (default: PyTorch's CPU index, a CPU-only build,
#                  about 190 MB). A CUDA build: TORCH_INDEX=https://download.pytorch.org/whl/cu128 (any
#                  CUDA index that has this version). TORCH_INDEX= (empty): whatever pip's own indexes
#                  resolve (from PyPI on Linux: the CUDA build, several GB with its nvidia-* packages).
#   If TORCH_INDEX cannot be reached, torch comes from pip's own indexes and a note says so (a machine
#   with a local wheel mirror, like the CI's, still gets its CPU wheel that way).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.installed
DEMO_ARGS ?=
TORCH_VERSION ?= 2.13.0
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
# `make test` runs the tests in this many worker processes (pytest-xdist): one per CPU this process may use (its
# affinity and its cgroup's quota: tools/cpus.py), at most 4 (each worker imports torch; the suite's own
# multi-process tests add to it). TEST_WORKERS=0: one process. The 15 slowest tests are listed at the end: CI keeps
# the suite under 15 minutes on 2 cores.
TEST_WORKERS ?= $(shell $(PYTHON) tools/cpus.py --max 4 2>/dev/null || echo 2)

.PHONY: demo test setup lint clean compose-check

# Ctrl-C ends the demo in order and it exits 130 (interrupted, by the shell's convention): a normal end here, not
# make's "Error 130"; any other status fails. `trap : INT` keeps the recipe's shell waiting for that orderly stop
# (without it the shell died with the signal and make said "Interrupt").
demo: $(STAMP)
	@trap : INT; $(VENV)/bin/foresight demo $(DEMO_ARGS) || { code=$$?; [ $$code -eq 130 ] || exit $$code; }

test: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --durations=15

# `docker compose up` for real: build the image, run the stack, check its log, compare with foresight demo, down
# (needs a running Docker engine; says in one line why not). COMPOSE_ARGS: --twice, --secure, --no-demo.
compose-check: $(STAMP)
	@FORESIGHT=$(VENV)/bin/foresight tools/compose_check.sh $(COMPOSE_ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check shared services tools tests

setup: $(STAMP)

# Python 3.11+ checked before anything is installed (a 3.10 venv downloaded torch, 4.6 GB, then failed on the
# project's requires-python and stayed); a venv Python could not finish (Debian without python3-venv) is removed,
# or every later make failed on it with "No module named pip".
$(VENV)/bin/python:
	@$(PYTHON) -c "import sys; sys.exit(sys.version_info < (3, 11))" || { echo "make setup: Foresight needs" \
	  "Python 3.11+, and $(PYTHON) is $$($(PYTHON) -V 2>&1); run make PYTHON=python3.11 (or newer)"; exit 1; }
	@$(PYTHON) -m venv $(VENV) || { rm -rf $(VENV); echo "make setup: '$(PYTHON) -m venv' failed (on Debian and" \
	  "Ubuntu: apt install python3-venv), and the half-made $(VENV) is removed"; exit 1; }
	$(PIP) install --quiet --upgrade pip

# torch first, from TORCH_INDEX when it answers (see the top of this file), then the project. Its build backend
# goes into the venv once and the project installs without build isolation: an isolated build fetched setuptools
# from the network on every reinstall (after a pull touched pyproject.toml), and `make demo` failed offline.
$(STAMP): pyproject.toml | $(VENV)/bin/python
	@$(PY) -c "import torch" 2>/dev/null || $(MAKE) --no-print-directory torch
	$(PIP) install --quiet "setuptools>=77"
	$(PIP) install --quiet --no-build-isolation -e ".[dev]"
	touch $(STAMP)

# Probe the index first: an unreachable index would otherwise cost pip minutes of retries per package.
.PHONY: torch
torch: | $(VENV)/bin/python
	@if [ -n "$(TORCH_INDEX)" ] && why=$$($(PY) -c "import sys, urllib.request; \
	  urllib.request.urlopen(sys.argv[1].rstrip('/') + '/torch/', timeout=10)" "$(TORCH_INDEX)" 2>&1); then \
	  echo "installing torch==$(TORCH_VERSION) from $(TORCH_INDEX)"; \
	  $(PIP) install "torch==$(TORCH_VERSION)" --index-url "$(TORCH_INDEX)"; \
	else \
	  [ -z "$(TORCH_INDEX)" ] || echo "note: TORCH_INDEX $(TORCH_INDEX) cannot be reached" \
	    "($$(echo "$$why" | tail -n 1));" \
	    "installing torch==$(TORCH_VERSION) from pip's own indexes (the build they have: from PyPI on Linux," \
	    "the CUDA build, several GB)"; \
	  $(PIP) install "torch==$(TORCH_VERSION)"; \
	fi

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache *.egg-info
