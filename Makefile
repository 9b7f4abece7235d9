# gcdt — the two commands for users are `make reproduce` and `make test`.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.gcdt-installed
BENCH_STAMP := $(VENV)/.gcdt-bench-installed
PYTEST_ARGS ?=
PROFILE ?= quick
BACKEND ?= local
NOTEBOOKS := $(sort $(wildcard notebooks/[0-9]*.ipynb))

.PHONY: install test lint bench bench-tqc reproduce figures lab clean help

help:
	@echo "make install    create $(VENV) from environment/ (no-op when up to date)"
	@echo "make test       install, then run the test suite"
	@echo "make lint       ruff over gcdt/, tests/ and benchmarks/"
	@echo "make bench      throughput benchmarks -> results/bench/*.json"
	@echo "make bench-tqc  TQC+HER trained on Reach to success -> results/bench/tqc_her_reach.json"
	@echo "make reproduce  [PROFILE=smoke|quick|paper] [BACKEND=local|ray]: the notebooks in order,"
	@echo "                then every table (results/PROFILE/) and figure (figures/PROFILE/)"
	@echo "make figures    [PROFILE=...] re-render tables and figures from results/PROFILE/runs/"
	@echo "make lab        JupyterLab with the project's kernel"
	@echo "make clean      remove caches (keeps $(VENV) and artifacts/)"

install: $(STAMP)

# Rebuilt only when the pins or the package metadata change.
$(STAMP): environment/requirements.txt pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment/requirements.txt
	$(PY) -m pip install --quiet --no-deps -e .
	@touch $@

test: install
	$(PY) -m pytest $(PYTEST_ARGS)

lint: install
	$(VENV)/bin/ruff check gcdt tests benchmarks
	$(VENV)/bin/ruff format --check gcdt tests benchmarks

# Speed is measured here, never in unit tests. Do not run beside other heavy jobs: each
# benchmark compares its cells side by side in one run, and the summary lands in README.md.
bench: install $(BENCH_STAMP)
	$(PY) benchmarks/training_throughput.py
	$(PY) benchmarks/evaluator_throughput.py --task push
	for task in reach push pick_and_place; do \
	  $(PY) benchmarks/collection_throughput.py --task $$task || exit 1; done
	$(PY) benchmarks/dataset_io.py --task push
	$(PY) benchmarks/tqc_her.py throughput --learning-steps 100
	$(PY) benchmarks/run_costs.py
	$(PY) benchmarks/end_to_end.py
	$(PY) benchmarks/summary.py --readme

# The benchmarks' optional extra: HuggingFace transformers, the authors' model.
$(BENCH_STAMP): $(STAMP) environment/bench-requirements.txt
	$(PY) -m pip install --quiet -r environment/bench-requirements.txt
	@touch $@

# TQC+HER trained on Reach (sparse and dense) to >= 95 % success: ~20 minutes on 2 cores.
bench-tqc: install
	$(PY) benchmarks/tqc_her.py reach
	$(PY) benchmarks/summary.py --readme

# The notebooks in order, executed by papermill into build/ (git-ignored); tables and
# figures land in results/$(PROFILE)/ and figures/$(PROFILE)/.
reproduce: install
	@$(VENV)/bin/gcdt sweep --profile $(PROFILE) --backend $(BACKEND) --dry-run > /dev/null
	@mkdir -p build/notebooks/$(PROFILE)
	@started=$$(date +%s); \
	for nb in $(NOTEBOOKS); do \
	  echo "== $$nb ($(PROFILE), $(BACKEND))"; \
	  $(PY) -m papermill --cwd notebooks --log-level WARNING -p profile $(PROFILE) \
	    -p backend $(BACKEND) $$nb build/notebooks/$(PROFILE)/$$(basename $$nb) || exit 1; \
	done; \
	$(VENV)/bin/gcdt report --profile $(PROFILE) --backend $(BACKEND) \
	  --wall-seconds $$(( $$(date +%s) - started ))

# Re-render the tables and figures from results/$(PROFILE)/runs/ alone.
figures: install
	$(VENV)/bin/gcdt report --profile $(PROFILE)

lab: install
	$(PY) -m ipykernel install --user --name gcdt --display-name "gcdt (.venv)"
	$(VENV)/bin/jupyter lab notebooks/

clean:
	rm -rf .pytest_cache .ruff_cache build *.egg-info
	find . -name __pycache__ -type d -prune -not -path './$(VENV)/*' -exec rm -rf {} +
