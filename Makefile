# Two entry points do all set-up on a fresh machine (see README):
#   make demo   -> virtual environment, Rust build, end-to-end demo on the simulated world
#   make test   -> virtual environment, Rust build, cargo tests of the core crates, pytest
#                  (all but the tests of the installed wheel, which make release-check runs)
#   make test-quick -> pytest without the tests marked slow: a developer's loop (CI runs make test)
#   make lint   -> ruff (lint, format), mypy on the package, clippy and rustfmt
#   make docs   -> the documentation site (mkdocs.yml) into site/, warnings as errors
#   make release-check -> the manylinux wheel and the sdist, checked as a lab would install them,
#                  and the tests marked release (the wheel installed in a fresh environment)
#
# Every build shares target/ and compiles each shared crate with the same profile (release) and
# the same features (cargo resolves the whole workspace for the tests, the extension's crate
# included; see rust/python/Cargo.toml), so whichever runs second reuses what the first
# compiled: `make test` after `make demo` adds only the test-only crates and test binaries.
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=
# pytest's worker processes (pytest-xdist): one per core.
PYTEST_WORKERS ?= auto
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
# uv installs the Python dependencies in parallel: seconds where pip took a minute or more.
# It lives in the environment, put there by pip (pinned here and nowhere else).
UV := "uv>=0.9,<1"
# `uv pip install -v` prints the build backend's output among its own debug lines; keep cargo's
# progress and what was installed, and show the end of the whole log if the install fails.
SHOW_BUILD := sed -u -n -E -e 's/^DEBUG +//' -e '/^ *(Compiling|Finished|Built |Installed)/ s/^ */    /p'
define uv_install
	@log=$$(mktemp); $(PY) -m uv pip install --python $(PY) -v $(1) 2>&1 | tee "$$log" | $(SHOW_BUILD) \
		|| { tail -n 40 "$$log" | sed -e 's/^DEBUG //'; rm -f "$$log"; exit 1; }; rm -f "$$log"
endef

.PHONY: venv install install-test install-lint demo wheel lint docs test test-rust test-python clean
.PHONY: test-quick
.PHONY: release-tools wheel-aarch64 sdist release-check

venv:
	@test -x $(PY) || { echo "==> creating the virtual environment $(VENV)"; python3 -m venv $(VENV); }
	@$(PY) -m pip install --quiet --upgrade pip $(UV)

# The package and its runtime dependencies: all the demo needs.
install: venv
	@echo "==> installing aptkt: Python dependencies, then the Rust core (release build: a few"
	@echo "    minutes on 2 cores the first time, seconds once target/ holds it)"
	$(call uv_install,-e .)

install-test: venv
	@echo "==> installing aptkt with the test dependencies (Rust core: see above)"
	$(call uv_install,-e ".[test]")

install-lint: venv
	$(call uv_install,-e ".[lint]")

demo: install
	@echo "==> aptkt demo (simulated world: 8 objects, 7 actions, 20 trials; 3 runs per method)"
	$(VENV)/bin/aptkt demo

# The release tools, pinned together here and nowhere else. maturin links the extension with
# zig against glibc 2.17's symbols (manylinux2014) whatever glibc the build machine has;
# maturin >= 1.15 carries the cargo-zigbuild that handles current Rust targets' link flags.
RELEASE_TOOLS := "maturin>=1.16,<2" "ziglang>=0.14.1,<0.15" "auditwheel>=6.8,<7" "twine>=6.1,<8"
MANYLINUX := manylinux2014
DIST := dist
ARCH := $(shell uname -m)
# maturin finds zig as `python3 -m ziglang` on the PATH.
ZIG_PATH := PATH="$(abspath $(VENV))/bin:$$PATH"

release-tools: venv
	@$(PY) -m uv pip install --python $(PY) --quiet $(RELEASE_TOOLS)

# dist/aptkt-<version>-cp310-abi3-manylinux2014_<arch>.manylinux_2_17_<arch>.whl. The zig
# linker is part of every crate's build settings, so this build does not reuse the editable
# install's crates: it compiles the workspace once more into target/<arch>-unknown-linux-gnu/
# (reused by the next `make wheel`; build scripts and macros are shared): about 2 minutes on
# 2 cores in a fresh clone (docs/install.md).
wheel: release-tools
	@echo "==> building the $(MANYLINUX) wheel (a full release build the first time)"
	rm -f $(DIST)/aptkt-*_$(ARCH).whl
	$(ZIG_PATH) $(PY) -m maturin build --release --zig --compatibility $(MANYLINUX) \
		--target $(ARCH)-unknown-linux-gnu --interpreter $(PY) --out $(DIST)

# Cross-built for 64-bit ARM (needs `rustup target add aarch64-unknown-linux-gnu`); it cannot
# run here, so CI does not build it (docs/install.md).
wheel-aarch64: release-tools
	rm -f $(DIST)/aptkt-*_aarch64.whl
	$(ZIG_PATH) $(PY) -m maturin build --release --zig --compatibility $(MANYLINUX) \
		--target aarch64-unknown-linux-gnu --out $(DIST)

# dist/aptkt-<version>.tar.gz: the Rust workspace and the Python package; installing it needs
# a Rust toolchain.
sdist: release-tools
	rm -f $(DIST)/aptkt-*.tar.gz
	$(PY) -m maturin sdist --out $(DIST)

# The wheel's manylinux tag (auditwheel), both archives' metadata (twine), then the wheel
# installed into a fresh environment of every Python the classifiers name and the sdist into the
# oldest's, each running the README's example and a learning run from a table
# (tests/packaging/release_check.py).
# SDIST_INSTALL=no skips building the sdist: a full Rust build from scratch (docs/install.md).
SDIST_INSTALL ?= yes
release-check: install-test wheel sdist
	@echo "==> release check"
	$(PY) tests/packaging/release_check.py --wheel "$$(ls $(DIST)/aptkt-*_$(ARCH).whl)" \
		--sdist "$$(ls $(DIST)/aptkt-*.tar.gz)" --manylinux $(MANYLINUX) \
		$(if $(filter no,$(SDIST_INSTALL)),--no-sdist-install)
	@echo "==> the tests of the installed wheel (marked release)"
	APTKT_WHEEL="$$(ls $(DIST)/aptkt-*_$(ARCH).whl)" $(PY) -m pytest -m release tests/packaging $(PYTEST_ARGS)

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

# The tests marked release install the manylinux wheel, a second full Rust build (zig): they
# belong to make release-check, which CI runs after this.
test-python: install-test
	@echo "==> Python tests (those marked release: make release-check)"
	$(PY) -m pytest -n $(PYTEST_WORKERS) -m "not release" $(PYTEST_ARGS)

test: test-rust test-python

# A developer's loop: the Python tests but those marked slow (the long end-to-end runs: killed
# processes, dropped links, the demo, the installed wheel), no Rust tests, no wheel. CI runs
# `make test` and `make release-check`, which together run everything.
test-quick: install-test
	@echo "==> Python tests without those marked slow"
	$(PY) -m pytest -n $(PYTEST_WORKERS) -m "not slow and not release" $(PYTEST_ARGS)

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
