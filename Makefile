# Two commands do all the set-up:  `make run` (reproduce the paper) and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= results
STAMP  := $(VENV)/.installed

.PHONY: run test docs lint bench clean

# pyproject.toml gives compatible ranges; constraints.txt the exact tested versions.
CONSTRAINTS := constraints.txt

$(STAMP): pyproject.toml $(CONSTRAINTS)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c $(CONSTRAINTS) -e '.[test,docs]'
	touch $(STAMP)

# --force: `make run` regenerates $(OUT) (every aiofl command refuses an existing non-empty
# --out without it; aiofl replaces only a folder it wrote, as a whole)
run: $(STAMP)
	$(BIN)/aiofl reproduce --out $(OUT) --force

# the tests run on every core (pytest-xdist; a test file stays on one worker, so its
# fixtures are built once, and the files reading the session's reproduce run share one:
# tests/conftest.py); they share one kernel cache (tests/conftest.py); the 25
# slowest tests are listed at the end (where the suite's time goes)
test: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples docs/conf.py docs/_ext
	$(BIN)/python -m pytest -n auto --dist loadfile --durations=25

# the manual (docs/): strict, warnings are errors, the gallery's examples executed;
# open docs/_build/html/index.html.  The examples use the tests' kernel cache (tests/conftest.py)
# unless AIOFL_CACHE_DIR is set, so after `make test` they compile nothing.
docs: $(STAMP)
	AIOFL_CACHE_DIR="$${AIOFL_CACHE_DIR:-$(CURDIR)/.aiofl-cache}" \
		$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples docs/conf.py docs/_ext
	$(BIN)/ruff format --check src tests benchmarks examples docs/conf.py docs/_ext

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_engine.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache build src/*.egg-info \
		docs/_build docs/auto_examples docs/reference/api docs/sg_execution_times.rst
