# Two commands do everything on a fresh clone: `make train` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install train test test-slow test-all fuzz lint house docs bench bench-full tensorboard clean

install: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@echo "making $(VENV) and installing the package with every extra (about 2 minutes)..."
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --progress-bar on -e ".[dev,all,docs,zoo]" -c constraints.txt
	$(PY) -m ipykernel install --sys-prefix --name python3 >/dev/null
	$(PY) scripts/warm_kernels.py  # numba's kernels, compiled once (1-2 minutes on 2 cores)
	touch $(STAMP)

train: $(STAMP)  ## default Q-learning job: the four reference targets of the two-bay tank
	$(PY) -m aftir_rl.train q_table

# One process per core (pytest-xdist), a test file per process, one BLAS/torch thread each so
# the processes do not slow each other down.
PYTEST := OMP_NUM_THREADS=1 $(PY) -m pytest -q -n auto --dist loadfile

test: $(STAMP)  ## the test suite (fast; long checks are marked slow and run by test-all)
	$(PYTEST) -m "not slow"

test-slow: $(STAMP)  ## the slow tests but the fuzzer's: after `make test` and `make fuzz`, every test has run once
	$(PYTEST) -m "slow and not fuzz"

test-all: $(STAMP)  ## every test, fast and slow
	$(PYTEST)

# Faults: the fuzzer, FUZZ_CASES mutated run directories for each of view, evaluate, rollout,
# rank_checkpoints, check and export, as many tanks (tank show) and Minari datasets (--demos)
# (test-all runs 5 each; test-slow leaves them here), then Ctrl-C at SIGINT_MOMENTS
# random moments of each long command, one at a time so that no other process slows its exit
# (about 40 minutes on 2 cores).
FUZZ_CASES ?= 2000
SIGINT_MOMENTS ?= 20
fuzz: $(STAMP)
	AFTIR_FUZZ_CASES=$(FUZZ_CASES) OMP_NUM_THREADS=1 $(PY) -m pytest -q -rP -n 2 --dist load tests/cli/test_fuzz_runs.py
	AFTIR_SIGINT_MOMENTS=$(SIGINT_MOMENTS) OMP_NUM_THREADS=1 $(PY) -m pytest -q -rP tests/cli/test_sigint_moments.py

lint: $(STAMP)
	$(PY) -m ruff check aftir_launch.py aftir_rl tests benchmarks scripts examples docs/_ext docs/conf.py
	$(PY) -m ruff format --check aftir_launch.py aftir_rl tests benchmarks scripts examples docs/_ext docs/conf.py
	$(PY) -m mypy

# A review aid, not a test: the largest modules, functions and module docstrings; fails nothing.
house: $(STAMP)
	$(PY) scripts/house_report.py

# The documentation site into docs/_build/html, offline, warnings as errors; the env pages and
# the CLI reference are generated from the package as it builds (docs/_ext/aftir_docs.py).
docs: $(STAMP)
	OMP_NUM_THREADS=1 $(VENV)/bin/sphinx-build -W --keep-going -q -b html docs docs/_build/html
	@echo "open docs/_build/html/index.html"

# The benchmark tables of docs/benchmarks.md. `make bench`: every script and every method on
# smaller fixed sets with shorter budgets (--quick, said above each table), about 4 minutes on
# 2 cores; `make bench-full`: the full sets and the 10 s budgets, the numbers of the docs
# (about 28 minutes, 11 of them the physics check's 24 motions, 6 RLlib beside SB3).
bench: $(STAMP)  ## every benchmark table, quick
	$(PY) benchmarks/bench_tank.py --quick
	$(PY) benchmarks/bench_posture.py --quick
	$(PY) benchmarks/bench_icra2014.py --quick
	$(PY) benchmarks/bench_st2014.py --quick
	$(PY) benchmarks/bench_arm.py --quick
	$(PY) benchmarks/bench_motion.py --quick
	$(PY) benchmarks/bench_goal.py --quick
	$(PY) benchmarks/bench_render.py --quick
	$(PY) benchmarks/bench_arm_ftl.py --quick
	$(PY) benchmarks/bench_fields.py --quick
	$(PY) benchmarks/bench_tank_cost.py --quick
	$(PY) benchmarks/bench_physics.py --quick
	OMP_NUM_THREADS=1 $(PY) benchmarks/bench_rllib.py --quick
	$(PY) -m aftir_rl.bench --quick

bench-full: $(STAMP)  ## every benchmark table of docs/benchmarks.md, full
	$(PY) benchmarks/bench_tank.py
	$(PY) benchmarks/bench_posture.py
	$(PY) benchmarks/bench_icra2014.py
	$(PY) benchmarks/bench_st2014.py
	$(PY) benchmarks/bench_arm.py
	$(PY) benchmarks/bench_motion.py
	$(PY) benchmarks/bench_goal.py
	$(PY) benchmarks/bench_render.py
	$(PY) benchmarks/bench_arm_ftl.py
	$(PY) benchmarks/bench_fields.py
	$(PY) benchmarks/bench_tank_cost.py
	$(PY) benchmarks/bench_physics.py
	OMP_NUM_THREADS=1 $(PY) benchmarks/bench_rllib.py --json benchmarks/results/rllib.json
	$(PY) -m aftir_rl.bench

tensorboard: $(STAMP)
	$(VENV)/bin/tensorboard --logdir runs

clean:  ## also numba's caches (a kernel's cache does not see edits to the kernels it calls)
	rm -rf runs .pytest_cache build *.egg-info docs/_build
	find aftir_rl -name "*.nb[ic]" -delete
