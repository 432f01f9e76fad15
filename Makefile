# Two commands do all the set-up: `make demo` and `make test`.
# Each creates .venv when it is missing, installs torch (CPU wheel) first, then pecli with its dev extra.
# `make docs` adds the docs extra and builds the documentation site into site/ (a broken link fails it).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pecli-installed
DOCS_STAMP := $(VENV)/.pecli-docs-installed

.PHONY: install demo test lint docs bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[dev]"
	@touch $(STAMP)

install: $(STAMP)

DEMO_ZOO := runs/demo-zoo

# Train a pursuer on the small scenario against the greedy evader (a few CPU-minutes),
# then play the result against greedy and draw one episode.
demo: install
	rm -rf $(DEMO_ZOO)/demo
	$(VENV)/bin/pecli train pursuer --config configs/quick.yaml --opponent greedy --zoo $(DEMO_ZOO) --name demo
	$(VENV)/bin/pecli play --pursuer $(DEMO_ZOO)/demo/pursuer/final.zip --evader greedy --config configs/quick.yaml \
		--episodes 500 --seed 0
	$(VENV)/bin/pecli play --pursuer $(DEMO_ZOO)/demo/pursuer/final.zip --evader greedy --config configs/quick.yaml \
		--episodes 1 --seed 1 --render runs/demo.gif

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

bench: install
	$(PY) benchmarks/bench_sim.py

clean:
	rm -rf $(VENV) build site *.egg-info .pytest_cache
