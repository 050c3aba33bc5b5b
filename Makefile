# Everything runs from a local virtual environment (.venv) that the targets create.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# Run the core (ROS-free) tests also against Ubuntu 24.04's numpy.
OLD_NUMPY ?= 1.26.4
OLD_VENV ?= .venv-numpy126

.PHONY: venv browser test test-core-old-numpy lint demo bench bench-one-core soak docs docs-check clean

$(BIN)/.installed: setup.py package.xml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[all]'
	touch $@

venv: $(BIN)/.installed

lint: venv
	$(BIN)/ruff check .

# The dashboard's browser test (test/test_dashboard.py): Debian's headless Chromium and its driver,
# installed when missing (CI runs as root on a fresh machine).
browser:
	@test -x /usr/bin/chromedriver || (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver)

test: venv lint browser test-core-old-numpy
	GAIT_REQUIRE_BROWSER=1 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST $(BIN)/pytest -q test

$(OLD_VENV)/bin/.installed: setup.py
	$(PYTHON) -m venv $(OLD_VENV)
	$(OLD_VENV)/bin/python -m pip install -q --upgrade pip
	$(OLD_VENV)/bin/python -m pip install -q "numpy==$(OLD_NUMPY)" -e '.[test,fast,analysis,bags]'
	touch $@

test-core-old-numpy: $(OLD_VENV)/bin/.installed
	$(OLD_VENV)/bin/python -c "import numpy; assert numpy.__version__ == '$(OLD_NUMPY)', numpy.__version__"
	$(OLD_VENV)/bin/pytest -q -p no:cacheprovider test/test_kernels.py test/test_process.py \
		test/test_matcher.py -k "not million"

# The main job: start estimator_node, stream the Multispeed recording into it at its real rate
# (230 Hz, about 62 s) and print what `ros2 topic echo mode/phase` would show, then a summary.
demo: venv
	$(BIN)/gait-estimator demo

bench: venv
	mkdir -p out
	$(BIN)/gait-estimator bench --modes 7,70,700 --json out/bench.json

# The embedded proxy (docs/performance.md): the matcher benchmark and bench-node on one core.
bench-one-core: venv
	mkdir -p out
	taskset -c 0 $(BIN)/gait-estimator bench --modes 7,70,700 --json out/bench_one_core.json
	taskset -c 0 $(BIN)/gait-estimator bench-node --profile --json out/bench_node_one_core.json

# The long soak of test/test_faults.py (not in CI, which runs 150,000 samples): 1.8 million
# samples with 1 kHz stamps (30 minutes of input) through estimator_node, as fast as it answers.
SOAK_SAMPLES ?= 1800000
soak: venv
	ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST GAIT_SOAK_SAMPLES=$(SOAK_SAMPLES) $(BIN)/pytest -q -s test/test_faults.py -k soak

# The measured tables in README.md and docs/: rebuild every benchmarks/results/*/tables.md from the
# results there (no benchmark is rerun; the reference agreement runs `process` on 3,000 samples,
# benchmarks/samples.py the commands whose output docs/ shows, in docs-check too), then copy each
# section into its <!-- BEGIN name --> block. Rerunning the benchmarks themselves:
# docs/performance.md, "Regenerating the numbers".
docs: venv
	$(BIN)/python benchmarks/performance.py
	$(BIN)/python benchmarks/node.py
	$(BIN)/python benchmarks/cross_session.py --tables-only
	$(BIN)/python benchmarks/accuracy.py --tables-only
	$(BIN)/python benchmarks/teach.py --tables-only
	$(BIN)/python benchmarks/imu.py --tables-only
	$(BIN)/python benchmarks/contract.py --tables-only
	$(BIN)/python -m benchmarks.common --update-docs

docs-check: venv
	$(BIN)/python -m benchmarks.common --check-docs

clean:
	rm -rf $(VENV) $(OLD_VENV) build install log out *.egg-info
