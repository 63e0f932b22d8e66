# Two commands on a fresh machine with only python3:  make demo  and  make test.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= out

.PHONY: demo test test-all lint bench sample-logs clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --upgrade pip
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[test]'
	@touch $(STAMP)

## demo: set up .venv, then run the main job on sample_logs/ (report + rerun recording in $(OUT)/)
demo: $(STAMP)
	$(BIN)/workbench demo --out $(OUT)

## test: set up .venv, then the whole test suite (headless)
test: $(STAMP)
	$(BIN)/python -m pytest

## test-all: the suite including the slow tests (full fuzz runs, large studies)
test-all: $(STAMP)
	$(BIN)/python -m pytest -m ''

lint: $(STAMP)
	$(BIN)/ruff check workbench adapters tests bench

## bench: speed ratios against the peer libraries, written to bench/results.md
bench: $(STAMP)
	$(BIN)/python bench/run_all.py

## sample-logs: regenerate sample_logs/ bit-identically from the fixed seed
sample-logs: $(STAMP)
	$(BIN)/python -m workbench.cli.sample_logs sample_logs

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache build *.egg-info
