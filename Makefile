# Two commands for a fresh machine with Python >= 3.11 (see README):
#   make run   - set up .venv and run the daemon on the simulated robot (one demo round)
#   make test  - set up .venv and run the whole test suite (what CI runs)
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp

.PHONY: help run test hil lint bench mutation clean

help:
	@echo "make run       the daemon on the simulated robot (rowc, 250 Hz): one demo round of"
	@echo "               moves (~20 s), a summary, then it exits; Ctrl-C stops it sooner"
	@echo "make test      lint, type check and the whole test suite (what CI runs)"
	@echo "make hil       the hardware-in-the-loop tests on a kernel vcan0 (docs/hil.md)"
	@echo "make bench     the kinematics benchmark (benchmarks/ has the others)"
	@echo "make mutation  mutation testing (hours; MODULES=\"supervisor torques\" JOBS=2 for a"
	@echo "               selection; docs/mutation.md; tools/mutation.py --help)"
	@echo "make clean     remove the venv and the caches"

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

# the hardware-in-the-loop tests (tests/tools/test_hil.py) run on a kernel SocketCAN vcan0: this
# machine's, or inside User-Mode Linux (tools/hil.py; docs/hil.md); `test` runs them where it
# can, and says why where it cannot
test: $(STAMP) lint
	$(BIN)/python -m pytest -m "not hil"
	$(BIN)/python tools/hil.py --if-possible

hil: $(STAMP)
	$(BIN)/python tools/hil.py

# Mutation testing of the safety-relevant modules (docs/mutation.md); hours, not part of `test`.
# MODULES="supervisor torques" JOBS=2 make mutation  runs a selection
mutation: $(STAMP)
	$(BIN)/python -c 'import cosmic_ray' 2>/dev/null || $(BIN)/python -m pip install --quiet -e '.[dev,mutation]'
	$(BIN)/python tools/mutation.py --jobs $(or $(JOBS),1) $(MODULES)

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_kinematics.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .kernel-cache
