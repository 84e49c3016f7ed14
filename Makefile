# Two commands for a fresh machine with Python >= 3.11 (see README):
#   make run   - set up .venv and run the main job
#   make test  - set up .venv and run the whole test suite (what CI runs)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp

.PHONY: run test lint bench mutation clean

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "cdprctl needs Python >= 3.11, found " + sys.version.split()[0])'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/cdprctl run --config config/rowc.toml --sim --rate 250

lint: $(STAMP)
	$(BIN)/ruff check cdprctl drivers sim_backend tests benchmarks tools
	$(BIN)/mypy

test: $(STAMP) lint
	$(BIN)/python -m pytest

# Mutation testing of the safety-relevant modules (docs/mutation.md); hours, not part of `test`.
# MODULES="supervisor torques" JOBS=2 make mutation  runs a selection
mutation: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[dev,mutation]'
	$(BIN)/python tools/mutation.py --jobs $(or $(JOBS),1) $(MODULES)

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_kinematics.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
