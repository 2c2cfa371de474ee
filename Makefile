# Two entry points do all set-up on a fresh machine (see README):
#   make demo   -> virtual environment, Rust build, end-to-end demo on the simulated world
#   make test   -> virtual environment, Rust build, cargo tests of the core crates, pytest
#
# Both builds share target/ and compile every shared crate with the same profile (release) and
# the same features (cargo resolves the whole workspace for the tests, the extension's crate
# included; see rust/python/Cargo.toml), so whichever runs second reuses what the first
# compiled: only the test-only crates (proptest, the test binaries) are added.
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c

.PHONY: install demo test test-rust test-python clean

install:
	@test -x $(PY) || { echo "==> creating the virtual environment $(VENV)"; python3 -m venv $(VENV); }
	@echo "==> installing Python dependencies and building aptkt (Rust core, release profile;"
	@echo "    a few minutes on 2 cores the first time, seconds once target/ is built)"
	@$(PY) -m pip install --quiet --upgrade pip
	@$(PY) -m pip install -v -e ".[test,bench]" 2>&1 \
		| grep -E --line-buffered "^ *(Compiling|Finished|Built|Installing collected|Successfully installed)|error|ERROR" \
		| sed -u -e 's/^ */    /'
	@echo "==> aptkt installed in $(VENV)"

demo: install
	@echo "==> aptkt demo (simulated world: 8 objects, 7 actions, 20 trials; 3 runs per method)"
	$(VENV)/bin/aptkt demo

test-rust:
	@echo "==> Rust tests of the core crates (release profile, reusing the extension's build)"
	cargo test --release --workspace

test-python: install
	@echo "==> Python tests"
	$(PY) -m pytest $(PYTEST_ARGS)

test: test-rust test-python

clean:
	rm -rf target $(VENV) python/aptkt/_core*.so
