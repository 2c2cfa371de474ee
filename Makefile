# Two entry points do all set-up on a fresh machine (see README):
#   make demo   -> virtual environment, Rust build, end-to-end demo on the simulated world
#   make test   -> virtual environment, Rust build, cargo tests of the core crates, pytest
#   make lint   -> ruff (lint, format), mypy on the package, clippy and rustfmt
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=

.PHONY: venv install install-test install-lint demo wheel lint test test-rust test-python clean

venv:
	@test -x $(PY) || python3 -m venv $(VENV)
	@$(PY) -m pip install --quiet --upgrade pip

# The package and its runtime dependencies: all the demo needs.
install: venv
	$(PY) -m pip install --quiet -e .

install-test: venv
	$(PY) -m pip install --quiet -e ".[test]"

install-lint: venv
	$(PY) -m pip install --quiet -e ".[lint]"

demo: install
	$(VENV)/bin/aptkt demo

# dist/aptkt-<version>-cp310-abi3-<platform>.whl; maturin shares cargo's target/ with the
# editable install, so only what differs is rebuilt.
wheel: venv
	$(PY) -m pip install --quiet "maturin>=1.8,<2"
	rm -f dist/aptkt-*.whl
	$(PY) -m maturin build --release --interpreter $(PY) --out dist

# Clippy lints that argue with the numerical kernels' idioms, allowed for the workspace:
# index loops over several parallel arrays, `!(a > b)` comparisons that reject NaN on purpose,
# kernels that take each array as its own argument, constants written with the digits they were
# published with, and the nested slice types of the kernel interfaces.
CLIPPY_ALLOW := -A clippy::needless_range_loop -A clippy::neg_cmp_op_on_partial_ord \
	-A clippy::too_many_arguments -A clippy::excessive_precision -A clippy::type_complexity

# Static gates. mypy reads python/aptkt with the core's stub (_core.pyi), so it needs the
# package's dependencies (numpy's types) but not the compiled extension.
lint: install-lint
	$(VENV)/bin/ruff check python tests benches
	$(VENV)/bin/ruff format --check python tests benches
	$(VENV)/bin/mypy
	cargo clippy --workspace --all-targets -- -D warnings $(CLIPPY_ALLOW)
	cargo fmt --all -- --check

test-rust:
	cargo test --release --workspace --exclude aptkt-python

# tests/packaging installs the wheel into a fresh virtual environment.
test-python: install-test wheel
	APTKT_WHEEL="$$(ls dist/aptkt-*.whl)" $(PY) -m pytest $(PYTEST_ARGS)

test: test-rust test-python

clean:
	rm -rf target dist $(VENV) python/aptkt/_core*.so
