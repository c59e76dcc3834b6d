# The two commands of the README. Each creates .venv and installs what it needs by itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test bench clean

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e '.[test]'  # the versions the figures were measured with
	# numba's kernels into its cache, once: else the first search, and each process of the parallel tests,
	# compiles them (about 30 s each for the planner's and the simulator's renderer, side by side here)
	$(VENV)/bin/syt-onboard compile & renderer=$$!; $(VENV)/bin/syt-offboard compile && wait $$renderer
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/syt-offboard demo --out demo-out

# -n 3 on 2 cores: many tests wait on real time (agents paced like a robot, Zenoh round trips), and a
# third worker computes through those waits (session 55, idle, back to back: 4:37 against 5:35 with two).
# --maxschedchunk 1: tests go to the workers a few at a time, not in blocks of a hundred, so the long
# tests (collected first, see tests/conftest.py) are shared between them
test: $(STAMP)
	$(PY) -m pytest -q -n 3 --maxschedchunk 1 --durations=10

bench: $(STAMP)
	$(VENV)/bin/syt-onboard bench --json

clean:
	rm -rf $(VENV) demo-out .pytest_cache
