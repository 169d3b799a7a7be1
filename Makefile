# Two commands do all set-up: `make train` and `make test`. Each creates the
# virtual environment it needs (in .venv) from pyproject.toml.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
RUN_DIR ?= runs/tsp-$(shell date +%Y%m%d-%H%M%S)
ITERATIONS ?= 200

.PHONY: install train test device-check device-run clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

# The main job: a short PiZero training on TSP10 on a local Ray instance, then
# an evaluation of the trained agent against the exact optimum.
train: $(STAMP)
	$(BIN)/pizero train --env tsp --run-dir $(RUN_DIR) --iterations $(ITERATIONS) --eval-every 20
	$(BIN)/pizero eval $(RUN_DIR) --episodes 1000

test: $(STAMP)
	JAX_PLATFORMS=cpu RAY_USAGE_STATS_ENABLED=0 $(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=15

# On a machine with an NVIDIA GPU: the gpu extra, the GPU tests, the bench with
# GPU workers and short TSP/Collect trainings, into one JSON under docs/bench/
# (scripts/device_check.py). Without a GPU it says so and exits 0.
device-check:
	$(PYTHON) scripts/device_check.py $(DEVICE_CHECK_ARGS)

# On a machine with an NVIDIA GPU, about 8 minutes: the GPU tests, the population rollout from 64 to 32768
# pairs on the GPU (and cross sections, also with XLA's command buffers), and the Ray trainer with one and two
# GPU workers, into one JSON under docs/bench/ (scripts/device_run.py; --cpu-rehearsal tries it on the CPU,
# DEVICE_RUN_ARGS='--learn tsp' trains instead). Without a GPU it says so and exits 0.
device-run:
	$(PYTHON) scripts/device_run.py $(DEVICE_RUN_ARGS)

clean:
	rm -rf $(VENV) .pytest_cache
