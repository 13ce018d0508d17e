# Two commands do everything on a fresh machine: `make run` and `make test`.
# Both create .venv and install the project (uv when available, pip otherwise), compiled to bytecode at install
# as pip does (uv does not by default): where PYTHONDONTWRITEBYTECODE is set, as on CI, every process would
# otherwise compile its libraries from source each start (a testbed: 10-14 s to its address, 3.5-4 s compiled).
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PYTHON ?= python3

.PHONY: run test test-fast bench plan-demo clean

$(STAMP): pyproject.toml
	@$(PYTHON) -m pip install -q uv >/dev/null 2>&1 || true
	@if $(PYTHON) -m uv --version >/dev/null 2>&1; then \
	    $(PYTHON) -m uv venv -q --allow-existing $(VENV) && \
	    $(PYTHON) -m uv pip install -q --compile-bytecode --python $(PY) -e '.[dev]'; \
	else \
	    $(PYTHON) -m venv $(VENV) && $(PY) -m pip install -q -e '.[dev]'; \
	fi
	@touch $(STAMP)

# make run ARGS="--port 8101 --time-scale 5": any `twb up` options
run: $(STAMP)
	$(VENV)/bin/twb up $(ARGS)

# Two workers (CI has two cores); --dist loadfile keeps a test file on one worker, so a module's
# testbed fixture starts once.  One file alone: $(PY) -m pytest tests/test_x.py
test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder  # in tests/conftest.py's order: longest first

# The inner loop: everything but the tests marked browser, postgres, ray or slow (pyproject.toml; tests/conftest.py
# marks them): no Chromium, PostgreSQL or Ray needed, no testbed process started.  Under 2 minutes on 2 cores.
FAST := not browser and not postgres and not ray and not slow
test-fast: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile -m "$(FAST)"

bench: $(STAMP)
	$(PY) bench/planners.py && $(PY) bench/metrics.py && $(PY) bench/sim.py && $(PY) bench/controllers.py && $(PY) bench/protocol.py && $(PY) bench/scheduler.py && $(PY) bench/server.py && $(PY) bench/study.py && $(PY) bench/closed_loop.py && $(PY) bench/fleet_live.py && $(PY) bench/fleet_playback.py && $(PY) bench/export.py && $(PY) bench/scale.py --runs 1000

clean:
	rm -rf $(VENV) .pytest_cache
