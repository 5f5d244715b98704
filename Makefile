# The whole set-up: `make demo` and `make test`. Both create .venv and install what they need.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-under-load lint bench clean

# The suite runs in TEST_WORKERS processes (pytest-xdist), each test module kept in one worker
# so its module fixtures start once; `make test TEST_WORKERS=0` runs it in one process.
# Five on two cores: a fifth of the suite's worker time waits on real time (simulators, browsers,
# servers' throttles), and a fifth worker fills those gaps (benchmarks/bench_suite.py, 2026-11-27,
# quiet: 4 workers 278 s, 5 workers 254 s for +2 % CPU; beside two burners 360 s and 340 s; six
# gained 8 s more quiet but overloaded the real-time INDI pass enough to miss its join; two
# back-to-back pairs on a slower host that evening: five 250 s and 285 s, six 246 s and 305 s).
# Modules are handed out in collection order, the longest first (tests/session_order.py): xdist's
# default would sort them by their number of tests, which put the few long real-time tests last.
TEST_WORKERS ?= 5
PYTEST := $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadscope --no-loadscope-reorder

# The suite starts hundreds of Python processes (xdist workers, `vs` servers and CLIs, devices):
# each compiled our sources and pytest's rewritten test modules again where the environment
# says PYTHONDONTWRITEBYTECODE (collection alone: 11 s of CPU per worker instead of 6 s).
# Bytecode goes to the __pycache__ folders git ignores.
unexport PYTHONDONTWRITEBYTECODE

$(PY):
	$(PYTHON) -m venv $(VENV)

SETUP_SCRIPTS := $(sort $(wildcard setup/*.sh))
SETUP_LIBS := $(wildcard setup/lib/*.bash)

# --no-compile: pip would byte-compile every file of every package (about half of the
# install); Python compiles what a run imports the first time it imports it instead (a clean
# clone's `make test`, 2026-11-28: 3 min 59 s in all instead of 4 min 16 s, pytest unchanged).
$(STAMP): pyproject.toml $(SETUP_SCRIPTS) $(SETUP_LIBS) | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e '.[test]'
	for s in $(SETUP_SCRIPTS); do echo "== $$s"; bash $$s || exit 1; done
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/vs demo

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(PYTEST)

# The suite with two CPU-burning processes beside it (2 cores): nothing may depend on host speed.
test-under-load: $(STAMP)
	$(PY) -c 'while True: pass' & b1=$$!; $(PY) -c 'while True: pass' & b2=$$!; \
	trap 'kill $$b1 $$b2 2>/dev/null' EXIT; \
	$(VENV)/bin/ruff check . && $(PYTEST)

lint: $(STAMP)
	$(VENV)/bin/ruff check .

bench: $(STAMP)
	$(PY) -m pip install --quiet -e '.[test,bench]'
	for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
