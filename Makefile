# mobisense — set-up, demo and tests. Every target creates .venv if missing and installs into it.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-hostile test-fast lint bench docs notebooks clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[sweep,test,docs]"
	$(BIN)/python -m ipykernel install --sys-prefix --name python3 >/dev/null
	@# byte-compile the package as a regular (non-editable) install does: with PYTHONDONTWRITEBYTECODE set, every
	@# command would otherwise compile its modules again (≈ 60 ms of `mobisense validate`'s 0.3 s)
	$(BIN)/python -m compileall -q -j 0 __init__.py cli.py core ocp estimation formation >/dev/null
	touch $(STAMP)

demo: $(STAMP)  ## solve the default problem (problems/hussein2008.yaml) into out/hussein2008/
	$(BIN)/mobisense solve problems/hussein2008.yaml --out out/hussein2008
	@echo "the command is installed in $(BIN)/: run '$(BIN)/mobisense --help' (or 'source $(BIN)/activate')"

test: $(STAMP)  ## ruff + the whole test suite (tests and notebooks) + the documentation site: what CI runs
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -m "not hostile_full" --durations=30
	$(MAKE) docs

test-fast: $(STAMP)  ## the edit-test loop: everything but notebooks and tests marked slow
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -m "not slow and not notebook" -q

test-hostile: $(STAMP)  ## every case of the hostile-input suite (≈ 340 runs; prints the table of outcomes)
	$(BIN)/python -m pytest tests/hostile -q

docs: $(STAMP)  ## the documentation site into site/ (mkdocs build --strict: any warning is an error)
	NO_MKDOCS_2_WARNING=1 MPLBACKEND=Agg $(BIN)/mkdocs build --strict --quiet

notebooks: $(STAMP)  ## execute notebooks/*.ipynb in place and store their outputs (figures) in them
	$(BIN)/python docs/tools/execute_notebooks.py notebooks/*.ipynb

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)  ## performance targets with PASS/MISS, ratios measured in one run (not part of the tests)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf out .pytest_cache build site *.egg-info
