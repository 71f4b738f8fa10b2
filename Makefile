# Two commands do everything on a fresh machine with Python 3.11:
#   make demo   -- run the main job on the shipped data
#   make test   -- run the test suite
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast lint bench venv clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/jaxgrav demo --out demo_output --force

# --max-worker-restart 0: pytest-xdist (--dist loadfile) hangs for ever, workers idle, when a
# worker dies and is restarted (seen with rare XLA:CPU aborts while compiling); without a
# restart the run ends, failed, and the whole suite runs once more.
XDIST  := -n 2 --dist loadfile --max-worker-restart 0

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q $(XDIST) tests || { \
	  echo "make test: the run failed; running the whole suite once more (a worker crash ends a run)"; \
	  $(BIN)/python -m pytest -q $(XDIST) tests; }

# the edit loop: the suite without the example scripts' smoke runs
test-fast: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q $(XDIST) tests --ignore=tests/examples

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/jaxgrav bench --quick --force --out bench.md

clean:
	rm -rf $(VENV) demo_output .pytest_cache .ruff_cache
