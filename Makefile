# foottof developer entry points. Each target creates/uses the local virtualenv .venv.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo learn wheels test test-integration test-slow lint bench terrain-png render-deps clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,export]"
	touch $(STAMP)

# Main job on a CPU-sized default: a short training run (configs/cpu.py, ~2 min), then the best
# ToF policy (policies/stage1, what policies/latest links to) crossing stepping stones at
# difficulty 0.36 (eval.difficulty_fraction 0.45; 63 % of such episodes succeed): DEMO_SEED draws
# a grid-stones tile it crosses to the goal (499 steps, success; tests/test_analysis.py checks
# it, a slow test). Plots, trace and a video with the foot rays over terrain shaded by height;
# then the flat-ground policy's episode (policies/flat).
DEMO_OUT := runs/demo_analysis
DEMO_SEED := 1
demo: $(STAMP) render-deps
	$(PY) train.py --config configs/cpu.py
	$(PY) evaluate.py --analyze --source tof --checkpoint policies/stage1 --config configs/stage1_cpu.py --config.eval.difficulty_fraction=0.45 --config.eval.seed=$(DEMO_SEED) --out $(DEMO_OUT)/stones
	$(PY) evaluate.py --analyze --source tof --checkpoint policies/flat --config configs/flat.py --out $(DEMO_OUT)/flat
	@echo "[demo] stones: $(DEMO_OUT)/stones/rollout_tof.mp4 (video), $(DEMO_OUT)/stones/analysis_tof.png (plots); flat ground: $(DEMO_OUT)/flat/"

# Learning check from scratch on flat ground (configs/flat.py): a new run runs/flat-<time>, then its
# learning curve (success, falls, return, length, level, speed vs env steps) as CSV + PNG.
learn: $(STAMP)
	$(PY) train.py --config configs/flat.py $(LEARN_ARGS)
	$(PY) -m foottof.lab.curves runs/flat

# Offline install (e.g. a GPU machine without internet): every wheel the project needs, in wheels/.
# There: python3.11 -m venv .venv && .venv/bin/pip install --no-index --find-links wheels foottof
# For NVIDIA GPUs add JAX's CUDA wheels: make wheels WHEEL_EXTRA='jax[cuda12]'
wheels: $(STAMP)
	$(PY) -m pip wheel --wheel-dir wheels . $(WHEEL_EXTRA)

# Fast suite (what CI runs): everything not marked slow, plus lint.
test: $(STAMP) render-deps
	$(VENV)/bin/ruff check .
	JAX_PLATFORMS=cpu $(PY) -m pytest -m "not slow and not integration" -n 2 --dist loadfile --no-loadscope-reorder -q --durations=20

# What CI runs after `make test`, kept out of the fast suite by their length: the multi-process
# guarantees (145 s of CPU; 15 min on a crowded 2-core box: bench/NOTES.md item 18), the slow
# tests of tests/test_distributed.py, each with 2 processes on localhost (2 processes x 1 device
# equal 1 process x 2 devices through a resume; a killed process stops the run in one line and a
# resume continues; a hung one ends the others within the heartbeat; a full disk on either
# process stops both in one line each and a resume continues; train.py checks the env count
# against both processes' devices); and the GPU check's --dry_run (~4.5 min of MJX
# compiles on the CPU: tests/test_gpu_check.py), one test at a time (no -n). Before them, the
# single-process tests of over ~30 s each that keep the fast suite within 12 minutes (marked
# integration: a learning-rate resume, a wider head, the teacher pinning, long guidance and
# failure rollouts, bench/NOTES.md item 20), two at a time.
test-integration: $(STAMP)
	JAX_PLATFORMS=cpu $(PY) -m pytest -m integration -n 2 --dist loadfile -q
	JAX_PLATFORMS=cpu $(PY) -m pytest -m slow -q tests/test_distributed.py tests/test_gpu_check.py

test-slow: $(STAMP)
	JAX_PLATFORMS=cpu $(PY) -m pytest -m "slow or integration" -q

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

bench: $(STAMP)
	$(PY) bench/bench_env.py

# Headless OpenGL (Mesa EGL or OSMesa) for rollout videos; a no-op where present.
render-deps:
	bash .ci/render-deps.sh

terrain-png: $(STAMP)
	$(PY) -m foottof.terrain.preview --out docs/terrains.png

clean:
	rm -rf $(VENV) runs .pytest_cache
