# Two entry points do all set-up on a fresh machine (see README):
#   make demo   -> virtual environment, Rust build, end-to-end demo on the simulated world
#   make test   -> virtual environment, Rust build, cargo tests of the core crates, pytest
#   make lint   -> ruff (lint, format), mypy on the package, clippy and rustfmt
#   make docs   -> the documentation site (mkdocs.yml) into site/, warnings as errors
#
# Every build shares target/ and compiles each shared crate with the same profile (release) and
# the same features (cargo resolves the whole workspace for the tests, the extension's crate
# included; see rust/python/Cargo.toml), so whichever runs second reuses what the first
# compiled: `make test` after `make demo` adds only the test-only crates and test binaries.
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
# pip -v shows the build backend's output; keep cargo's progress lines and errors.
SHOW_BUILD := grep -E --line-buffered "^ *(Compiling|Finished|Built wheel|Successfully installed)|[Ee]rror" | sed -u -e 's/^ */    /'

.PHONY: venv install install-test install-lint demo wheel lint docs test test-rust test-python clean

venv:
	@test -x $(PY) || { echo "==> creating the virtual environment $(VENV)"; python3 -m venv $(VENV); }
	@$(PY) -m pip install --quiet --upgrade pip

# The package and its runtime dependencies: all the demo needs.
install: venv
	@echo "==> installing aptkt: Python dependencies, then the Rust core (release build: a few"
	@echo "    minutes on 2 cores the first time, seconds once target/ holds it)"
	@$(PY) -m pip install -v -e . 2>&1 | $(SHOW_BUILD)

install-test: venv
	@echo "==> installing aptkt with the test dependencies (Rust core: see above)"
	@$(PY) -m pip install -v -e ".[test]" 2>&1 | $(SHOW_BUILD)

install-lint: venv
	$(PY) -m pip install --quiet -e ".[lint]"

demo: install
	@echo "==> aptkt demo (simulated world: 8 objects, 7 actions, 20 trials; 3 runs per method)"
	$(VENV)/bin/aptkt demo

# dist/aptkt-<version>-cp310-abi3-<platform>.whl; maturin shares cargo's target/ with the
# editable install, so only what differs is rebuilt.
wheel: venv
	@echo "==> building the wheel (reuses target/)"
	@$(PY) -m pip install --quiet "maturin>=1.8,<2"
	rm -f dist/aptkt-*.whl
	$(PY) -m maturin build --release --interpreter $(PY) --out dist

# Static gates. mypy reads python/aptkt with the core's stub (_core.pyi), so it needs the
# package's dependencies (numpy's types) but not the compiled extension. Clippy's lints are
# configured in Cargo.toml ([workspace.lints]).
lint: install-lint
	$(VENV)/bin/ruff check python tests benches
	$(VENV)/bin/ruff format --check python tests benches
	$(VENV)/bin/mypy
	cargo clippy --workspace --all-targets -- -D warnings
	cargo fmt --all -- --check

test-rust:
	@echo "==> Rust tests of the core crates (release profile, reusing the extension's build)"
	cargo test --release --workspace

# tests/packaging installs the wheel into a fresh virtual environment.
test-python: install-test wheel
	@echo "==> Python tests"
	APTKT_WHEEL="$$(ls dist/aptkt-*.whl)" $(PY) -m pytest $(PYTEST_ARGS)

test: test-rust test-python

# The site's tools alone: mkdocstrings reads the docstrings from python/ without importing aptkt,
# so the docs need no Rust build. pip reads the pinned [docs] list from pyproject.toml's
# dependency group without installing the package itself. Not --quiet: mkdocs 1.6 then stops
# counting warnings, and --strict lets a broken link pass.
docs: venv
	@echo "==> building the documentation site into site/ (mkdocs --strict)"
	@$(PY) -m pip install --quiet --group docs
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

clean:
	rm -rf target dist site $(VENV) python/aptkt/_core*.so
