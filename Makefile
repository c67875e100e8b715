# Everything runs from .venv, created on first use from pyproject.toml.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/framechain demo --out demo

lint: $(STAMP)
	$(VENV)/bin/ruff check framechain tests benchmarks
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# Notebooks run after the tests and one at a time: two Jupyter kernels starting at once (one per
# xdist worker) can race for the same ZMQ port and the kernel dies before it answers.
test: lint
	$(PY) -m pytest -q -n 2 tests
	$(PY) -m pytest -q -p no:xdist --nbmake notebooks

bench: $(STAMP)
	$(PY) benchmarks/run.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
