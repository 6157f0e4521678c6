# Two entry points: `make run` (the main job) and `make test` (the whole suite).
# Everything is installed into .venv by these rules; nothing is needed by hand.
PYTHON ?= python3
VENV ?= .venv
BIN = $(VENV)/bin
OUT ?= out

.PHONY: run test bench bench-estimate clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# the kernels Cython compiles at install (setup.py): editing one rebuilds its extension module
KERNELS = $(wildcard src/delaykit/*/*.pxd) $(patsubst %.pxd,%.py,$(wildcard src/delaykit/*/*.pxd))

$(VENV)/.installed: $(BIN)/python pyproject.toml setup.py $(KERNELS)
	$(BIN)/pip install -q -e .
	touch $@

$(VENV)/.test-installed: $(VENV)/.installed
	$(BIN)/pip install -q -e '.[test,bench,cluster]'
	# Debian's chromium for the test that renders the report page (the test skips, saying why, without it)
	command -v chromium >/dev/null 2>&1 || (timeout 900 sh -c 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium' >/dev/null 2>&1 || echo "chromium could not be installed; the page-rendering test will be skipped")
	touch $@

run: $(VENV)/.installed
	$(BIN)/delaykit reproduce --out $(OUT)/paper
	$(BIN)/delaykit demo --out $(OUT)/demo

# the real-time flights measure timing: they run alone, after the rest, with no other worker taking the CPU
test: $(VENV)/.test-installed
	$(BIN)/python -m pytest -n 2 -q -m "not realtime"
	$(BIN)/python -m pytest -q -m realtime

bench: $(VENV)/.test-installed
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_general.py
	$(BIN)/python benchmarks/bench_roots.py
	$(BIN)/python benchmarks/bench_frequency.py
	$(BIN)/python benchmarks/bench_estimate.py

bench-estimate: $(VENV)/.test-installed
	$(BIN)/python benchmarks/bench_estimate.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .hypothesis
