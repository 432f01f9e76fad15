# Two commands do all the set-up: `make demo` and `make test`.
# Each creates .venv when it is missing, installs torch (CPU wheel) first, then pecli with its dev extra.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.pecli-installed

.PHONY: install demo test bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[dev]"
	@touch $(STAMP)

install: $(STAMP)

demo: install
	$(VENV)/bin/pecli play --pursuer pure-pursuit --evader greedy --config configs/quick.yaml \
		--episodes 200 --seed 0 --render runs/demo.gif

test: install
	$(PY) -m pytest -q

bench: install
	$(PY) benchmarks/bench_sim.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
