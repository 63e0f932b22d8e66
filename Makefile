# Two commands on a fresh machine with only python3:  make demo  and  make test.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    ?= out
# The exact version of every distribution .venv gets, used as pip constraints (see `make lock`).
LOCK   := requirements.lock
LATEST := .venv-latest
PIP     = -m pip --disable-pip-version-check

.PHONY: demo test test-all test-latest lint bench sample-logs lock clean readme-screenshot

# A changed lock reinstalls: pip moves every package to its pinned version (pip itself first).
$(STAMP): pyproject.toml $(LOCK)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python $(PIP) install --quiet --constraint $(LOCK) pip
	$(BIN)/python $(PIP) install --quiet --constraint $(LOCK) -e '.[test]'
	@touch $(STAMP)

## demo: set up .venv, then run the main job on sample_logs/ (report + rerun recording in $(OUT)/)
demo: $(STAMP)
	$(BIN)/workbench demo --out $(OUT)

## readme-screenshot: the README's picture (docs/viewer.png, docs/viewer.json) of the demo's first view, taken by
## rerun's own viewer from $(OUT)/demo.rrd (made first if missing); tests/test_readme.py says when it is stale
readme-screenshot: $(STAMP)
	@test -s $(OUT)/demo.rrd || $(BIN)/workbench demo --out $(OUT)
	$(BIN)/python -m workbench.viewer.screenshot $(OUT)/demo.rrd docs/viewer.png

# The suite runs on pytest-xdist workers, one per core (`make test TEST_WORKERS=0` runs it in one process);
# PYTEST_ARGS adds options (`make test PYTEST_ARGS='-k viewer'`). It prints its duration and the machine's load,
# and a selection with no tests in it (pytest's exit status 5) is not a failure.
TEST_WORKERS ?= auto
PYTEST_ARGS  ?=
RUN_PYTEST = start=$$(date +%s); status=0; $(1) -m pytest -n $(TEST_WORKERS) $(2) $(PYTEST_ARGS) || status=$$?; \
	if [ $$status -eq 5 ]; then echo "$@: no tests collected"; status=0; fi; \
	echo "$@: $$(( $$(date +%s) - start )) s on $$(nproc) cores, $$(uptime | sed 's/.*\(load average\)/\1/')"; \
	exit $$status

## test: set up .venv, then the fast suite (headless; tests marked slow: make test-all); prints its duration
test: $(STAMP)
	@$(call RUN_PYTEST,$(BIN)/python,)

## test-all: the suite including the slow tests (full fuzz runs, large studies)
test-all: $(STAMP)
	@HYPOTHESIS_PROFILE=explore; export HYPOTHESIS_PROFILE; $(call RUN_PYTEST,$(BIN)/python,-m '')

## test-latest: the fast suite in $(LATEST), installed without the lock: the newest releases pyproject.toml allows
test-latest:
	@test -x $(LATEST)/bin/python || $(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python $(PIP) install --quiet --upgrade pip
	$(LATEST)/bin/python $(PIP) install --quiet --upgrade --upgrade-strategy eager -e '.[test]'
	@$(LATEST)/bin/python $(PIP) freeze --all --exclude-editable > $(LATEST)/freeze.txt
	@echo "versions that differ from $(LOCK) (< lock, > latest):"
	@grep -v '^#' $(LOCK) | diff - $(LATEST)/freeze.txt | grep '^[<>]' || echo "  none"
	@$(call RUN_PYTEST,$(LATEST)/bin/python,)

lint: $(STAMP)
	$(BIN)/ruff check workbench adapters tests bench

## bench: speed ratios against the peer libraries, written to bench/results.md
bench: $(STAMP)
	$(BIN)/python bench/run_all.py

## sample-logs: regenerate sample_logs/ bit-identically from the fixed seed
sample-logs: $(STAMP)
	$(BIN)/python -m workbench.cli.sample_logs sample_logs

## lock: rewrite $(LOCK) from a fresh venv with .[test] installed unconstrained (then commit it)
lock:
	@set -e; tmp=$$(mktemp -d); trap 'rm -rf "$$tmp"' EXIT; \
	$(PYTHON) -m venv "$$tmp/venv"; py="$$tmp/venv/bin/python"; \
	"$$py" $(PIP) install --quiet --upgrade pip; \
	"$$py" $(PIP) install --quiet --upgrade --upgrade-strategy eager -e '.[test]'; \
	{ echo "# Every distribution .venv gets, pinned; the Makefile installs with --constraint $(LOCK)."; \
	  echo "# Made by \`make lock\`: a fresh venv, pip install --upgrade pip, then pip install --upgrade"; \
	  echo "# --upgrade-strategy eager -e '.[test]' without constraints (the newest releases pyproject.toml allows,"; \
	  echo "# the venv's own setuptools too), pip freeze --all --exclude-editable (--all keeps pip and setuptools:"; \
	  echo "# osqp needs setuptools at run time)."; \
	  echo "# $$("$$py" -c 'import platform as p; print(p.python_implementation(), p.python_version(), "on", p.system(), p.machine())'), $$(date -u +%Y-%m-%d). Do not edit: run make lock."; \
	  "$$py" $(PIP) freeze --all --exclude-editable; } > "$$tmp/lock"; \
	if grep -v '^#' "$$tmp/lock" | grep -Evq '^[A-Za-z0-9._-]+==[A-Za-z0-9.!]+$$'; then \
	  echo "lock: not a plain name==version pin (a URL, a local +version or an editable):" >&2; \
	  grep -v '^#' "$$tmp/lock" | grep -Ev '^[A-Za-z0-9._-]+==[A-Za-z0-9.!]+$$' >&2; exit 1; fi; \
	cp "$$tmp/lock" $(LOCK).tmp; mv -f $(LOCK).tmp $(LOCK); \
	echo "lock: wrote $(LOCK) ($$(grep -vc '^#' $(LOCK)) pins)"

clean:
	rm -rf $(VENV) $(LATEST) $(OUT) .pytest_cache .ruff_cache build *.egg-info
