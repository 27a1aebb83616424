# Two entry points, each self-contained from a fresh clone:
#   make demo   set up .venv, run one closed-loop CMPC episode (3 robots, 7 humans, the zoo's Social-LSTM)
#               printing its metrics, writing runs/demo/*.mcap and a plot
#   make test   set up .venv, lint (ruff), type-check (mypy), run the test suite (pytest)
#   make dist   build the sdist and the wheel (with the shipped model zoo) into dist/
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
# Datasets are never committed: use CROWDMPC_DATA if set, else the team's shared copy beside the clone.
CROWDMPC_DATA ?= $(abspath ../shared/data)
export CROWDMPC_DATA

.PHONY: demo test lint typecheck setup dist clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip >/dev/null
	# torch first and pinned: an unpinned torch pulls a multi-GB CUDA build
	$(BIN)/pip install torch==2.13.0
	$(BIN)/pip install -e '.[dev]'
	touch $@

setup: $(BIN)/.installed

demo: $(BIN)/.installed
	$(BIN)/crowdmpc simulate --controller cmpc --predictor social_lstm_eth --scenario circle \
		--robots 3 --humans 7 --episodes 1 --seed 0 --record runs/demo --plot runs/demo/episode.png

lint: $(BIN)/.installed
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# mypy reads its configuration (packages to check, CasADi treated as untyped) from pyproject.toml.
typecheck: $(BIN)/.installed
	$(BIN)/mypy

# The slow tests (closed-loop batches, a real Ray sweep when Ray is installed) fit CI's budget: run them all,
# in a process per core (pytest-xdist; at most four), each test file whole in one process (--dist loadfile: a
# file's fixtures and order as written). One process took 715 s on CI and 1493 s on a slower CI host, over
# its 20 minutes; two take about 1 / 1.5 of one's time here (tests/pipelines/test_s*.py: 273 and 201 s in one
# process, 162 s in two, load 1.2-2.2 on 2 cores). `pytest` alone still runs them in one.
test: lint typecheck
	$(BIN)/python -m pytest -q -m "slow or not slow" -n auto --maxprocesses 4 --dist loadfile

# sdist first, then the wheel from the sdist (what a user's `pip install` gets); tests/test_wheel.py installs
# one into a fresh virtual environment and runs it outside the clone.
dist: $(BIN)/.installed
	$(BIN)/python -m build --no-isolation --outdir dist .

clean:
	rm -rf $(VENV) runs .pytest_cache .ruff_cache *.egg-info build dist
