# asset2sim — see README.md
PYTHON ?= python3.11
VENV ?= .venv
PY := $(VENV)/bin/python
CATALOG ?= catalog.yaml
DATASET ?=
WORKERS ?= 2
RUN ?=

TIMEZONE ?=

.PHONY: setup demo test test-cpu test-all test-lower map check-install flow serve failures bench bench-eval bench-catalog clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip setuptools wheel

setup: $(PY)  ## install asset2sim with [all] into .venv (every extra but mjx, newton, ovphysx, learn, maniskill, checkers; the exact versions of constraints/ci.txt)
	$(PY) -m pip install --quiet -e ".[all]" -c constraints/ci.txt

demo: ## refine the built-in demo asset (no data needed)
	$(VENV)/bin/asset2sim demo --out out/demo

TEST_WORKERS ?= 2
# The test targets let Python cache bytecode (__pycache__, ignored by git) even where PYTHONDONTWRITEBYTECODE is
# set: every process of the suite (the workers, the command-line and flow tests' children) would else compile the
# package and rewrite the test modules again (docs: DEVELOPERS.md, "Tests in tiers").
TEST_ENV := env -u PYTHONDONTWRITEBYTECODE
test: ## the fast tiers: unit and integration tests (end-to-end tests, marked slow, left out) on TEST_WORKERS processes
	$(TEST_ENV) $(PY) -m pytest -m "not slow" -q -n $(TEST_WORKERS) --dist loadfile

test-cpu: ## the fast tiers as `make test`, then their CPU seconds per test and per module's collection (benchmarks/pytest_cpu.py): their cost without a shared machine's wall-clock noise
	rm -rf out/test_cpu
	$(TEST_ENV) PYTEST_CPU_DIR=out/test_cpu PYTHONPATH=$(CURDIR)/benchmarks $(PY) -m pytest -p pytest_cpu -m "not slow" -q -n $(TEST_WORKERS) --dist loadfile
	$(PY) benchmarks/pytest_cpu.py out/test_cpu

test-all: ## the whole suite, every tier (the end-to-end tier included; before a release), on TEST_WORKERS processes
	$(TEST_ENV) $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

LOWER_VENV ?= .venv-lower
test-lower: ## the fast tiers with the lowest versions pyproject.toml allows (constraints/lower.txt), in .venv-lower
	$(PYTHON) -m venv $(LOWER_VENV)
	$(LOWER_VENV)/bin/python -m pip install --quiet --upgrade pip setuptools wheel
	$(LOWER_VENV)/bin/python -m pip install --quiet -e ".[all]" -c constraints/lower.txt
	$(TEST_ENV) $(LOWER_VENV)/bin/python -m pytest -m "not slow" -q -n $(TEST_WORKERS) --dist loadfile

map: ## write DEVELOPERS.md's map of the code from the module docstrings (tests/test_docs.py checks it is current)
	$(PY) tools/code_map.py

check-install: ## build the wheel and install it beside ManiSkill, robosuite and torch in fresh environments (long; network)
	$(PY) benchmarks/check_install.py

flow: ## refine the dataset catalog.yaml names (DATASET=..., WORKERS=...)
	$(VENV)/bin/asset2sim flow --catalog $(CATALOG) $(if $(DATASET),--dataset $(DATASET)) --workers $(WORKERS)

serve: ## register and serve the nightly deployment
	$(VENV)/bin/asset2sim serve --catalog $(CATALOG) $(if $(DATASET),--dataset $(DATASET)) $(if $(TIMEZONE),--timezone $(TIMEZONE))

failures: ## failure-mode breakdown of the latest run from the Parquet catalog
	$(VENV)/bin/asset2sim failures --catalog $(CATALOG) $(if $(DATASET),--dataset $(DATASET)) $(if $(RUN),--run $(RUN))

bench: ## per-stage wall time of refine over the dev dataset
	$(PY) benchmarks/bench_refine.py

bench-catalog: ## failures queries on a synthetic catalog of 10^6 rows over 365 nightly runs (each under 2 s)
	$(PY) benchmarks/bench_catalog.py

bench-eval: ## evaluation time per asset and the independent re-implementation check
	$(PY) benchmarks/bench_evaluate.py --check

clean:
	rm -rf out bench data/refined/* .pytest_cache
