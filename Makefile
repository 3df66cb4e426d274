# armreach developer tasks. `make test` and `make demo` set everything up on a fresh clone.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install system-deps test test-slow test-no-mujoco test-py310 test-all lint demo bench clean

PROJECTS := pyproject.toml backends/pybullet/pyproject.toml backends/mujoco/pyproject.toml tasks/grasp/pyproject.toml \
	tasks/obstacles/pyproject.toml drivers/template/pyproject.toml constraints-cpu.txt
# Two steps into one venv: what training and the demo need, then the rest (sweeps, zoo, export,
# the arm corpus, test tools). No byte-compiling at install: Python compiles what it imports,
# once, and most of what the wheels hold is never imported (half the install's time). Where
# PYTHONDONTWRITEBYTECODE is set Python writes no cache itself: armreach_core.cli.precompile
# compiles what the commands import, once (2-3 s off every command's start).
PIP_INSTALL := $(BIN)/python -m pip install --quiet --no-compile -c constraints-cpu.txt
RUN_STAMP := $(VENV)/.installed-run

$(RUN_STAMP): $(PROJECTS)
	$(PYTHON) -m venv $(VENV)
	$(PIP_INSTALL) torch -e ".[rl]" -e backends/pybullet -e backends/mujoco -e tasks/grasp -e tasks/obstacles
	$(BIN)/python -m armreach_core.cli.precompile
	touch $(RUN_STAMP)

$(STAMP): $(RUN_STAMP)
	$(PIP_INSTALL) -e ".[rl,zoo,ray,sysid,deploy,dev]" -e drivers/template
	$(BIN)/python -m armreach_core.cli.precompile pytest xdist ray armreach_mydriver
	touch $(STAMP)

# A virtual display for the live-window (render_mode="human") tests, on Debian-like machines where we are root.
# Best effort: without it those tests skip and everything else runs.
system-deps:
	@if ! command -v xvfb-run >/dev/null 2>&1 && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb xauth >/dev/null) \
		|| echo "could not install xvfb: the live-window tests will skip"; \
	fi

install: $(STAMP) system-deps

# The everyday suite: a few minutes. Long integration runs (Ray sweeps, rl-zoo3, resumed
# trainings, every corpus arm) are marked slow and run by `make test-slow` (CI's second step).
# Both run TEST_JOBS tests at a time (pytest-xdist), then those marked `alone` (they time the
# machine or start a Ray worker per core) by themselves.
TEST_JOBS ?= 2
test: $(STAMP) system-deps
	$(BIN)/python -m pytest -m "not slow and not alone" -q -n $(TEST_JOBS)
	$(BIN)/python -m pytest -m "not slow and alone" -q

test-slow: $(STAMP) system-deps
	$(BIN)/python -m pytest -m "slow and not alone" -q -n $(TEST_JOBS) --durations=25
	$(BIN)/python -m pytest -m "slow and alone" -q --durations=10

# The same suite with mujoco unimportable: MuJoCo is optional, so everything else must pass without it.
# Training tests use PyBullet only and already ran in `make test`.
test-no-mujoco: $(STAMP)
	ARMREACH_TEST_HIDE=mujoco $(BIN)/python -m pytest -m "not slow and not training and not alone" -q -n $(TEST_JOBS)
	ARMREACH_TEST_HIDE=mujoco $(BIN)/python -m pytest -m "not slow and not training and alone" -q

# The env, its checks and the plugins on the oldest Python armreach supports (3.10), where one
# is installed: core, backends and grasp, no training stack (the CPU torch wheel is 3.11's).
# PyPI's MuJoCo for 3.10 is an older release, so MuJoCo is hidden as in test-no-mujoco.
# pyenv's shim answers `command -v python3.10` even where 3.10 is not the selected version, so
# each candidate is asked to run before it is taken.
PY310 ?= $(firstword $(foreach p,$(wildcard $(shell pyenv root 2>/dev/null)/versions/3.10*/bin/python3.10) \
	$(shell command -v python3.10 2>/dev/null),$(shell $(p) -c 'print("$(p)")' 2>/dev/null)))
VENV310 ?= .venv310
test-py310:
	@if [ -z "$(PY310)" ]; then echo "no python3.10 here: skipping the 3.10 run"; exit 0; fi; \
	if [ ! -f $(VENV310)/.installed ] || [ pyproject.toml -nt $(VENV310)/.installed ]; then \
		$(PY310) -m venv $(VENV310) && $(VENV310)/bin/python -m pip install --quiet --upgrade pip setuptools && \
		$(VENV310)/bin/python -m pip install --quiet -e ".[dev]" -e backends/pybullet -e backends/mujoco \
			-e tasks/grasp -e tasks/obstacles && \
		touch $(VENV310)/.installed || exit 1; \
	fi; \
	ARMREACH_TEST_HIDE=mujoco $(VENV310)/bin/python -m pytest -m "not slow and not training" -q -p no:cacheprovider

test-all: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/armreach bench --out runs/bench

demo: $(RUN_STAMP)
	$(BIN)/armreach experiment paper --seeds 1 --steps 2048 --steps fast-ppo=114688 --steps fast-sac=20000 --episodes 20 --fast --jobs 2 --out runs/demo

clean:
	rm -rf $(VENV) $(VENV310) build dist *.egg-info runs .pytest_cache .mypy_cache .ruff_cache
