# navreplay: the two commands a newcomer runs are `make demo` and `make test`.
# Both create or refresh .venv from pyproject.toml first; nothing else must be installed by hand.

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.navreplay-installed
DEV_STAMP := $(VENV)/.navreplay-dev-installed
export DVC_NO_ANALYTICS := 1
# dvc.yaml stages call the `navreplay` console script: run them with the venv first on PATH.
export PATH := $(CURDIR)/$(VENV)/bin:$(PATH)
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: demo test venv dev lint typecheck pytest bench clean-venv browser warm

venv: $(STAMP)

# The package and its runtime dependencies: all that `make demo` needs. uv (from PyPI, into
# the venv) installs them: the same releases as pip, in seconds rather than minutes.
UV := $(BIN)/uv pip install --quiet --python $(BIN)/python

$(STAMP): pyproject.toml Makefile
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "navreplay needs Python >= 3.11; found " + sys.version.split()[0] + " at $(PYTHON)")'
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet "uv>=0.9"
	$(UV) --editable .
	@touch $(STAMP)

# The development tools on top (pytest, ruff, mypy and stubs, import-linter, selenium): `make test`.
dev: $(DEV_STAMP)

$(DEV_STAMP): $(STAMP)
	$(UV) --group dev
	@touch $(DEV_STAMP)

demo: venv
	$(BIN)/dvc repro
	@$(BIN)/python -m navreplay.pipeline.cli where-reports

# mypy (one core, about 90 s cold) runs beside the suite rather than before it
test: lint
	@$(MAKE) --no-print-directory -j2 typecheck pytest

# lint-imports: the import contracts of pyproject.toml [tool.importlinter] (layers, no cycles);
# --no-cache: the import graph is rebuilt every time (well under a second), never read stale
lint: dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports --no-cache

# mypy checks pipeline/ and ingest/ under their installed names (navreplay.pipeline,
# navreplay.ingest) through these symlinks: it cannot follow the editable install's import hook
TYPECHECK_TREE := build/typecheck/navreplay

typecheck: dev
	@mkdir -p $(TYPECHECK_TREE)
	@for pkg in pipeline ingest; do ln -sfn ../../../$$pkg $(TYPECHECK_TREE)/$$pkg; done
	$(BIN)/mypy

# Headless Chromium for the report tests (tests/browser): Debian's chromium and chromium-driver,
# installed with apt when missing (CI runs `make test` as root on a fresh machine).
CHROMIUM := /usr/bin/chromium
CHROMEDRIVER := /usr/bin/chromedriver
# As root apt-get runs directly, otherwise through passwordless sudo; when neither works the
# browser tests skip and say why.
browser:
	@if [ ! -x $(CHROMIUM) ] || [ ! -x $(CHROMEDRIVER) ]; then \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; \
	  elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then SUDO="sudo -n"; \
	  else SUDO=none; fi; \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$SUDO" != none ]; then \
	    echo "installing chromium and chromium-driver (Debian packages) for the browser tests"; \
	    $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq && \
	    $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver \
	      >/dev/null || echo "apt-get could not install chromium: the browser tests will skip"; \
	  else \
	    echo "no $(CHROMIUM) and neither root nor sudo for apt-get: the browser tests will skip"; \
	  fi; \
	fi

# The suite runs on PYTEST_WORKERS processes (pytest-xdist), each taking whole test files so
# that a module's cached drives and runs are built once; PYTEST_WORKERS=0 runs it in one. Files
# are handed out in the suite's order (tests/conftest.py: the slow ones first), not xdist's
# default of the most tests first.
# The 15 slowest tests are listed at the end (where the time goes).
PYTEST_WORKERS ?= 2

# Every filter's kernel compiled once, before the suite (beside mypy): cold, the two workers
# would otherwise compile the same kernels at once, each in its own process, and the first
# test of every filter family would pay its compile (on a fresh clone about a third of the
# suite's time). Warm, it loads the cache in seconds.
warm: dev
	$(BIN)/navreplay warm

pytest: dev browser warm
	NAVREPLAY_REQUIRE_BROWSER=$$(test -x $(CHROMIUM) && test -x $(CHROMEDRIVER) && echo 1) \
	  $(BIN)/pytest -n $(PYTEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=15

bench: dev
	$(BIN)/python -m benchmarks

clean-venv:
	rm -rf $(VENV)
