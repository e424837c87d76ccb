# Two commands do all the set-up on a fresh machine (Python 3.10+ with venv):
#   make demo   - the assembly task, a bag and a report (creates .venv on first use)
#   make test   - lint, type check and the test suite, 9-15 minutes on 2 cores (creates .venv on first use)
#   make test-slow - the long experiments left out of `make test` (pytest -m slow; docs/testing.md)
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
OUT ?= out

.PHONY: demo test test-slow experiment bench lint bytecode clean

$(VENV)/.installed: setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,test,view,robots,sweep]'
	touch $@

demo: $(VENV)/.installed bytecode
	$(VENV)/bin/dualarm demo --output $(OUT)/demo

experiment: $(VENV)/.installed
	$(VENV)/bin/dualarm experiment assembly --output $(OUT)/experiment

$(VENV)/.bench-installed: $(VENV)/.installed
	$(PY) -m pip install --quiet -e '.[ros,test,view,robots,sweep,bench]'
	touch $@

bench: $(VENV)/.bench-installed
	$(VENV)/bin/dualarm bench --output $(OUT)/bench

# The package's bytecode, written here once: where PYTHONDONTWRITEBYTECODE is set (as on CI) no import writes it,
# and every node process would compile the sources again (0.4 s CPU of a node's 1.2 s start; docs/testing.md).
# Only changed sources are compiled again.
bytecode: $(VENV)/.installed
	$(PY) -m compileall -q dualarm_control dualarm_sim

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# The default run (docs/testing.md): the tests side by side on TEST_WORKERS pytest-xdist workers (whole modules
# each) and, beside them at idle CPU priority (SCHED_IDLE: they run only when no other task wants a core) on
# BACKGROUND_WORKERS xdist workers of their own (0: in one process; docs/testing.md), the `background` tests (no
# ROS node, no wall-clock verdict); then the `realtime` tests (verdicts on the wall clock),
# with what is left of the background run beside them at idle priority (SCHED_FIFO nodes are never preempted by
# it). Every test phase's duration and CPU time in $(OUT)/test-durations*.txt (CI prints them).
TEST_WORKERS ?= 2
BACKGROUND_WORKERS ?= 0
IDLE := $(shell chrt --idle 0 true >/dev/null 2>&1 && echo chrt --idle 0 || echo nice -n 19)
# the background run in a session of its own: Ctrl-C stops it and everything it started (planner workers too)
SESSION := $(shell setsid true >/dev/null 2>&1 && echo setsid)
test: lint bytecode
	@mkdir -p $(OUT); echo "$(IDLE) $(PY) -m pytest -q -n $(BACKGROUND_WORKERS) --dist loadfile -m 'background and not slow' >$(OUT)/test-background.log &"; \
	$(IDLE) $(SESSION) $(PY) -m pytest -q -n $(BACKGROUND_WORKERS) --dist loadfile -m 'background and not slow' \
	    --durations-file=$(OUT)/test-durations-background.txt \
	    >$(OUT)/test-background.log 2>&1 & background=$$!; trap 'kill -TERM -$$background 2>/dev/null || kill -TERM $$background 2>/dev/null' INT TERM; \
	echo "$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m 'not slow and not realtime and not background'"; \
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m 'not slow and not realtime and not background' \
	    --durations-file=$(OUT)/test-durations.txt; parallel=$$?; realtime=1; \
	if [ $$parallel = 0 ]; then \
	    echo "$(PY) -m pytest -q -m 'realtime and not slow'"; \
	    $(PY) -m pytest -q -m 'realtime and not slow' --durations-file=$(OUT)/test-durations-realtime.txt; \
	    realtime=$$?; fi; \
	wait $$background; background=$$?; echo "== $(OUT)/test-background.log"; cat $(OUT)/test-background.log; \
	[ $$parallel = 0 ] && [ $$realtime = 0 ] && [ $$background = 0 ]

test-slow: $(VENV)/.installed bytecode
	$(PY) -m pytest -q -m slow

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
