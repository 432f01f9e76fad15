# Two commands do all the set-up: `make demo` and `make test`.
# Each creates .venv when it is missing, installs torch (its CPU build, TORCH_INDEX below) first, then pecli with
# its dev extra.
# `make docs` adds the docs extra and builds the documentation site into site/ (a broken link fails it).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pecli-installed
DOCS_STAMP := $(VENV)/.pecli-docs-installed
# PyPI's Linux torch wheel is the CUDA build (several GB); this index holds the CPU one (torch==2.13.0+cpu), which pip
# prefers as the higher version. Where it cannot be reached (probed with urllib, which reads the environment's
# proxy variables, not pip.conf), torch comes from pip's own indexes.
# Empty it (make test TORCH_INDEX=) to use only pip's own configuration.
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu

.PHONY: install demo test lint docs release-check bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	@echo "installing torch 2.13.0 (the CPU build from TORCH_INDEX), then pecli and its dependencies into $(VENV): 2-3 minutes the first time"
	@if [ -n "$(TORCH_INDEX)" ] && $(PY) -c "import sys, urllib.request; urllib.request.urlopen(sys.argv[1], timeout=10)" "$(TORCH_INDEX)" 2>/dev/null; then \
		echo "$(PY) -m pip install --extra-index-url $(TORCH_INDEX) torch==2.13.0"; \
		$(PY) -m pip install --progress-bar on --extra-index-url "$(TORCH_INDEX)" "torch==2.13.0"; \
	else \
		echo "$(PY) -m pip install torch==2.13.0 (from pip's own indexes, $(if $(TORCH_INDEX),$(TORCH_INDEX) not reached,TORCH_INDEX empty); on Linux PyPI's is the CUDA build)"; \
		$(PY) -m pip install --progress-bar on "torch==2.13.0"; \
	fi
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
