# navreplay: the two commands a newcomer runs are `make demo` and `make test`.
# Both create or refresh .venv from pyproject.toml first; nothing else must be installed by hand.

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.navreplay-installed
export DVC_NO_ANALYTICS := 1
# dvc.yaml stages call the `navreplay` console script: run them with the venv first on PATH.
export PATH := $(CURDIR)/$(VENV)/bin:$(PATH)
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: demo test venv lint typecheck pytest bench clean-venv

venv: $(STAMP)

$(STAMP): pyproject.toml Makefile
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "navreplay needs Python >= 3.11; found " + sys.version.split()[0] + " at $(PYTHON)")'
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip>=25.1"
	$(BIN)/python -m pip install --quiet --editable . --group dev
	@touch $(STAMP)

demo: venv
	$(BIN)/dvc repro
	@$(BIN)/python -m pipeline.cli where-reports

test: lint typecheck pytest

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: venv
	$(BIN)/mypy

pytest: venv
	$(BIN)/pytest

bench: venv
	$(BIN)/python -m benchmarks

clean-venv:
	rm -rf $(VENV)
