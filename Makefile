# The two commands a fresh machine needs are `make demo` and `make test` (see README.md).
# Everything runs from the project's own virtual environment, created on first use.
VENV ?= .venv
BIN := $(VENV)/bin
PY := $(BIN)/python
PRESET ?= traj_descending_sine

.PHONY: setup setup-runtime lock test-distro demo test test-loaded test-fast test-slow lint typecheck bench bench-models soak soak-loaded faults lab-example figures \
	sample-bags shipped-models colcon clean

INSTALL_DEPS := scripts/setup_env.sh src/catheter_models/setup.py src/catheter_ros/setup.py src/catheter_driver/setup.py \
	src/catheter_control/setup.py scripts/build_interfaces.sh $(shell find ros2_ws/interfaces -type f)

## Everything, from requirements-lock.txt (hashes checked): runtime, training extra, tests.
setup: $(VENV)/.installed

$(VENV)/.installed: requirements-lock.txt $(INSTALL_DEPS)
	scripts/setup_env.sh $(VENV)

## What running the graph needs (requirements-runtime-lock.txt): no torch, no onnx.
setup-runtime: $(VENV)/.installed-runtime

$(VENV)/.installed-runtime: requirements-runtime-lock.txt $(INSTALL_DEPS)
	scripts/setup_env.sh --runtime $(VENV)

## Regenerate the locks and docker/constraints.txt from requirements*.txt (scripts/lock.sh).
lock:
	scripts/lock.sh

## The fast tests under Ubuntu 24.04's numpy, scipy, scikit-learn, matplotlib and numba (the
## versions the container image gets), in their own venv (requirements-distro-lock.txt).
DISTRO_VENV ?= .venv-distro
$(DISTRO_VENV)/.installed: requirements-distro-lock.txt $(INSTALL_DEPS)
	scripts/setup_env.sh --distro $(DISTRO_VENV)

# numba's kernel cache apart from .venv's: the two numba versions would overwrite each other's
# cache beside the sources, and the recompiles eat the lab tests' wall-time budgets.
test-distro: $(DISTRO_VENV)/.installed
	NUMBA_CACHE_DIR=$(abspath $(DISTRO_VENV))/numba-cache $(DISTRO_VENV)/bin/pytest -m "not slow"

## The main job: bring up the simulated rig as separate ROS 2 processes, follow a thesis
## trajectory, print the tracking report, save the plot and the bag.
demo: setup-runtime
	$(BIN)/follow_trajectory --sim --preset $(PRESET)

## All tests, the slow integration tests included (this is what .ci/run calls).
test: setup
	$(BIN)/pytest -m "slow or not slow" --durations=25

## All tests beside two busy-loop processes: the suite must hold on a shared machine.
test-loaded: setup
	scripts/with_cpu_hogs.sh 2 $(BIN)/pytest -m "slow or not slow"

## Fast tests only (no DDS graph, no colcon build).
test-fast: setup
	$(BIN)/pytest -m "not slow"

test-slow: setup
	$(BIN)/pytest -m slow

lint: setup
	$(BIN)/ruff check src tests bench scripts
	$(BIN)/ruff format --check src tests bench scripts

typecheck: setup
	$(BIN)/mypy

## Speed: the simulated rig, the c-LSTM's per-tick compute against the thesis's window, and
## the whole graph over DDS at 250 Hz and 1 kHz (about 4 minutes; run on an idle machine).
bench: setup
	$(PY) bench/bench_plant.py
	$(PY) bench/bench_clstm_step.py
	$(PY) bench/bench_graph_timing.py
	$(PY) bench/bench_lab.py

## Soak: the whole simulated graph at 1 kHz for 10 minutes with the recorder on; missed
## deadlines per minute, RSS per process and dropped messages in the bag (about 11 minutes;
## run it alone). Results: bench/results/soak.json and soak.png, and docs/reliability.md.
soak: setup
	$(PY) bench/bench_soak.py
	$(PY) scripts/soak_section.py bench/results/soak.json --docs docs/reliability.md

## The same beside two busy loops (a lab PC doing other work): bench/results/soak_loaded.json.
soak-loaded: setup
	$(PY) bench/bench_soak.py --hogs 2
	$(PY) scripts/soak_section.py bench/results/soak_loaded.json --docs docs/reliability.md

## Fault-injection suite (tests marked `fault`, about 3 minutes): every fault, its invariants
## and its time to a safe state, written into docs/reliability.md's table.
faults: setup
	FAULT_REPORT=bench/results/faults.json $(BIN)/pytest -m fault tests/integration
	$(PY) scripts/fault_table.py bench/results/faults.json --docs docs/reliability.md

## The lab's worked example (docs/lab.md): hidden pneumatic lag, diagnose, add, history.
lab-example: setup
	$(PY) scripts/lab_worked_example.py --docs

## The thesis's tables (8.1-8.4 modelling, 11.1-11.4 control) redone on the simulated rig,
## plus identification speed. About 25 minutes on 2 cores; see docs/benchmarks.md.
bench-models: setup
	$(PY) bench/bench_drdpi_identification.py
	$(PY) bench/bench_modelling.py
	$(PY) bench/bench_control.py

## Retrain the compensators shipped in catheter_control/data (c-LSTM, IDRDPI) from bags.
shipped-models: setup
	$(PY) scripts/train_shipped_models.py

figures: setup
	$(PY) scripts/plot_thesis_figures.py

sample-bags: setup
	$(PY) scripts/make_sample_bags.py

colcon: setup
	cd ros2_ws && ../$(BIN)/colcon build --symlink-install

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log
