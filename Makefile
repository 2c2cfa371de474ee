# Two entry points do all set-up on a fresh machine (see README):
#   make demo   -> virtual environment, Rust build, end-to-end demo on the simulated world
#   make test   -> virtual environment, Rust build, cargo tests of the core crates, pytest
VENV ?= .venv
PY := $(VENV)/bin/python
PYTEST_ARGS ?=

.PHONY: install demo test test-rust test-python clean

install:
	@test -x $(PY) || python3 -m venv $(VENV)
	@$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,bench]"

demo: install
	$(VENV)/bin/aptkt demo

test-rust:
	cargo test --release --workspace --exclude aptkt-python

test-python: install
	$(PY) -m pytest $(PYTEST_ARGS)

test: test-rust test-python

clean:
	rm -rf target $(VENV) python/aptkt/_core*.so
