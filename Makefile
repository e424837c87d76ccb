# Two commands do all the set-up on a fresh machine (Python 3.10+ with venv):
#   make demo   - the assembly task, a bag and a report (creates .venv on first use)
#   make test   - lint, type check and the test suite, about 9 minutes (creates .venv on first use)
#   make test-slow - the long experiments left out of `make test` (pytest -m slow; docs/testing.md)
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
OUT ?= out

.PHONY: demo test test-slow experiment bench lint clean

$(VENV)/.installed: setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,test,view,robots,sweep]'
	touch $@

demo: $(VENV)/.installed
	$(VENV)/bin/dualarm demo --output $(OUT)/demo

experiment: $(VENV)/.installed
	$(VENV)/bin/dualarm experiment assembly --output $(OUT)/experiment

$(VENV)/.bench-installed: $(VENV)/.installed
	$(PY) -m pip install --quiet -e '.[ros,test,view,robots,sweep,bench]'
	touch $@

bench: $(VENV)/.bench-installed
	$(VENV)/bin/dualarm bench --output $(OUT)/bench

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# The default run (docs/testing.md): the tests side by side on TEST_WORKERS pytest-xdist workers (whole
# modules each, longest first), then the `realtime` tests (verdicts on the wall clock) alone; every test
# phase's duration in $(OUT)/test-durations*.txt (CI prints them).
TEST_WORKERS ?= 2
test: lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m 'not slow and not realtime' --durations-file=$(OUT)/test-durations.txt
	$(PY) -m pytest -q -m 'realtime and not slow' --durations-file=$(OUT)/test-durations-realtime.txt

test-slow: $(VENV)/.installed
	$(PY) -m pytest -q -m slow

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
