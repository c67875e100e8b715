# Everything runs from .venv, created on first use from pyproject.toml.
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench fuzz clean bytecode

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

# framechain's modules compiled to bytecode, as pip leaves an installed package: a machine that sets
# PYTHONDONTWRITEBYTECODE would compile them from source in every command (0.18 s each; the tests run hundreds).
bytecode: $(STAMP)
	$(PY) -m compileall -q framechain

demo: bytecode
	$(VENV)/bin/framechain demo --out demo

lint: $(STAMP)
	$(VENV)/bin/ruff check framechain tests benchmarks
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# Notebooks run after the tests and one at a time: two Jupyter kernels starting at once (one per
# xdist worker) can race for the same ZMQ port and the kernel dies before it answers.
# MALLOC_PERTURB_: libx264 reads uninitialised memory at widths that are not a multiple of 64 (the tests' 224 px
# wrist videos), so the same frames encode differently from run to run and every camera-motion test would
# measure another video each time; glibc filling fresh allocations makes the generated videos the same bytes.
# The manual (docs/, mkdocs.yml) is built strictly into a scratch folder: a broken link or anchor fails.
test: lint bytecode
	MALLOC_PERTURB_=165 $(PY) -m pytest -q -n 2 tests
	$(PY) -m pytest -q -p no:xdist --nbmake notebooks
	site=$$(mktemp -d) && $(VENV)/bin/mkdocs build --strict --quiet --site-dir "$$site"; status=$$?; rm -rf "$$site"; exit $$status

bench: bytecode
	$(PY) benchmarks/run.py

# Damaged copies of the real logs (../shared/realdata) through info, tf, replay and attribute,
# then mutated chain, calibration and robot.yaml files (tools/fuzz_config.py) through info and
# attribute, then damaged LeRobot datasets (tools/fuzz_datasets.py) through info, tf and attribute:
# fails on a traceback, a hang, memory beyond the bound or an exit code other than 0 or 1 (and for
# a configuration or a dataset, an exit 1 that is not one line). Not part of `make test` (about 25
# minutes on 2 cores); the tests run a short fixed-seed part of each.
FUZZ_CASES ?= 10000
FUZZ_CONFIG_CASES ?= 1500
FUZZ_DATASET_CASES ?= 300
fuzz: $(STAMP)
	$(PY) tools/fuzz.py --cases $(FUZZ_CASES) --config-cases $(FUZZ_CONFIG_CASES) \
		--dataset-cases $(FUZZ_DATASET_CASES) --seed 0 --progress

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
