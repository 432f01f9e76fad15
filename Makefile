# Two commands do all the set-up: `make demo` and `make test`.
# Each creates .venv when it is missing, installs torch (CPU wheel) first, then pecli with its dev extra.
# `make docs` adds the docs extra and builds the documentation site into site/ (a broken link fails it).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pecli-installed
DOCS_STAMP := $(VENV)/.pecli-docs-installed

.PHONY: install demo test lint docs release-check bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	@echo "installing torch 2.13.0 (CPU wheel), then pecli and its dependencies into $(VENV): 2-3 minutes the first time"
	$(PY) -m pip install --progress-bar on "torch==2.13.0"
	@echo "torch installed; now pecli with its dev extra"
	$(PY) -m pip install --progress-bar on -e ".[dev]"
	@touch $(STAMP)

install: $(STAMP)

# The main job on the small scenario, end to end in about 2 CPU-minutes: a pursuer trained with the tuned settings,
# measured beside pure pursuit against the scripted evaders, exported to ONNX and played, drawn into runs/demo/.
demo: install
	$(VENV)/bin/pecli demo --out runs/demo

# Lint (ruff: rules and format) and types (mypy on the core packages, listed in pyproject.toml), then the suite.
lint: install
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m mypy

test: lint
	$(PY) -m pytest -q

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e ".[dev,docs]"
	@touch $(DOCS_STAMP)

# The site: every page in docs/, the CLI and config reference generated from the code (tools/docs_hooks.py),
# the Python API from the docstrings. --strict turns any warning (a broken link or anchor) into a failure.
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

# The sdist and wheel build, and the wheel installs in a fresh environment outside the repository and runs.
release-check: install
	$(PY) tools/release_check.py

bench: install
	$(PY) benchmarks/bench_sim.py

clean:
	rm -rf $(VENV) build dist site *.egg-info .pytest_cache
