# gcdt — the two commands for users are `make reproduce` and `make test`.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.gcdt-installed
PYTEST_ARGS ?=
PROFILE ?= quick
README_PROFILE ?= large
BACKEND ?= local
# A reproduction's own results and figures: never the published results/ and figures/.
REPRO_DIR ?= $(or $(GCDT_OUTPUTS),$(or $(GCDT_ARTIFACTS),artifacts)/reproduce)
NOTEBOOKS := $(sort $(wildcard notebooks/[0-9]*.ipynb))

.PHONY: install test lint bench bench-tqc reproduce publish figures datasets lab clean help

help:
	@echo "make install    create $(VENV) from environment/ (no-op when up to date)"
	@echo "make test       install, then run the test suite"
	@echo "make lint       ruff over gcdt/, tests/, benchmarks/, scripts/ and notebooks/"
	@echo "make bench      throughput benchmarks -> results/bench/*.json, docs/benchmarks.md"
	@echo "make bench-tqc  TQC+HER trained on Reach to success -> results/bench/tqc_her_reach.json"
	@echo "make reproduce  PROFILE=smoke|quick|standard|large|paper (default quick; its time: gcdt sweep --profile P --dry-run) [BACKEND=local|ray]:"
	@echo "                re-run the grid and every notebook into $(REPRO_DIR)/, then check"
	@echo "                the results against the published ones (results/PROFILE/)"
	@echo "make publish    (maintainers) make that reproduction the published results/ and figures/"
	@echo "make figures    [PROFILE=...] re-render tables and figures from results/PROFILE/runs/"
	@echo "make datasets   PROFILE=P: its expert and random data as Minari datasets in artifacts/minari,"
	@echo "                checked against results/PROFILE/datasets.json; docs/datasets.md"
	@echo "make lab        JupyterLab with the project's kernel"
	@echo "make clean      remove caches (keeps $(VENV) and artifacts/)"

install: $(STAMP)

# Rebuilt only when the pins or the package metadata change.
$(STAMP): environment/requirements.txt pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment/requirements.txt
	$(PY) -m pip install --quiet --no-deps -e .
	@# The notebooks name this kernel: papermill, nbval and JupyterLab find it in the venv.
	$(PY) -m ipykernel install --sys-prefix --name gcdt --display-name "gcdt (.venv)" > /dev/null
	@touch $@

test: install
	@echo "make test: the suite, then every notebook (nbval); about 15 min on 2 cores"
	$(PY) -m pytest $(PYTEST_ARGS)

lint: install
	$(VENV)/bin/ruff check gcdt tests benchmarks scripts notebooks
	$(VENV)/bin/ruff format --check gcdt tests benchmarks scripts notebooks

# Speed is measured here, never in unit tests. Do not run beside other heavy jobs: each
# benchmark compares its cells side by side in one run, and the summary lands in docs/benchmarks.md.
bench: install
	$(PY) benchmarks/training_throughput.py
	$(PY) benchmarks/evaluator_throughput.py --task push
	for task in reach push pick_and_place; do \
	  $(PY) benchmarks/collection_throughput.py --task $$task || exit 1; done
	$(PY) benchmarks/dataset_io.py --task push
	$(PY) benchmarks/tqc_her.py throughput
	$(PY) benchmarks/tqc_her_profile.py
	$(PY) benchmarks/run_costs.py
	$(PY) benchmarks/end_to_end.py
	$(PY) benchmarks/summary.py --docs

# TQC+HER trained on Reach (sparse and dense) to >= 95 % success: ~20 minutes on 2 cores.
bench-tqc: install
	$(PY) benchmarks/tqc_her.py reach
	$(PY) benchmarks/summary.py --docs

# Re-run the profile: the grid's runs, then the notebooks in order (papermill), with results,
# figures and executed notebooks in $(REPRO_DIR) (finished runs there are resumed, the published ones never
# count); then the tables and figures, and the check against the published results/PROFILE/.
reproduce: install
	@export GCDT_OUTPUTS="$(abspath $(REPRO_DIR))"; \
	$(VENV)/bin/gcdt sweep --profile $(PROFILE) --backend $(BACKEND) --dry-run > /dev/null || exit 2; \
	mkdir -p "$$GCDT_OUTPUTS/results/$(PROFILE)/notebooks"; \
	echo "Reproducing profile $(PROFILE) into $$GCDT_OUTPUTS"; \
	started=$$(date +%s); \
	$(VENV)/bin/gcdt sweep --profile $(PROFILE) --backend $(BACKEND) || exit 1; \
	for nb in $(NOTEBOOKS); do \
	  echo "== $$nb ($(PROFILE), $(BACKEND))"; \
	  $(PY) -m papermill --engine gcdt --cwd notebooks --log-level WARNING $$([ -t 1 ] || echo --no-progress-bar) \
	    -p profile $(PROFILE) \
	    -p backend $(BACKEND) $$nb "$$GCDT_OUTPUTS/results/$(PROFILE)/notebooks/$$(basename $$nb)" || exit 1; \
	done; \
	$(VENV)/bin/gcdt report --profile $(PROFILE) --backend $(BACKEND) \
	  --wall-seconds $$(( $$(date +%s) - started )) > /dev/null || exit 1; \
	$(VENV)/bin/gcdt compare --profile $(PROFILE)

# Maintainers: make the finished reproduction in $(REPRO_DIR) the published results/PROFILE/
# and figures/PROFILE/. README.md's results always show README_PROFILE's published results;
# they are regenerated after any publish, since they say which run files they share with
# other profiles.
publish: install
	$(VENV)/bin/gcdt publish --profile $(PROFILE) --from $(REPRO_DIR)
	env -u GCDT_OUTPUTS $(VENV)/bin/gcdt report --profile $(README_PROFILE) --readme

# Re-render the tables and figures from results/$(PROFILE)/runs/ alone.
figures: install
	env -u GCDT_OUTPUTS $(VENV)/bin/gcdt report --profile $(PROFILE)

# The profile's collections as Minari datasets in artifacts/minari (or $MINARI_DATASETS_PATH),
# checked against the published manifest results/PROFILE/datasets.json (written where there
# is none; maintainers replace it with `gcdt dataset build --profile P --write-manifest`), and
# the card docs/datasets.md regenerated from the manifests.
datasets: install
	env -u GCDT_OUTPUTS $(VENV)/bin/gcdt dataset build --profile $(PROFILE)
	$(VENV)/bin/gcdt dataset card

# Containers run as root, which JupyterLab refuses without --allow-root.
lab: install
	$(VENV)/bin/jupyter lab notebooks/ $(if $(filter 0,$(shell id -u)),--allow-root)

clean:
	rm -rf .pytest_cache .ruff_cache build *.egg-info
	find . -name __pycache__ -type d -prune -not -path './$(VENV)/*' -exec rm -rf {} +
