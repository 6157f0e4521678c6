# Two entry points: `make run` (the main job) and `make test` (the whole suite).
# Everything is installed into .venv by these rules; nothing is needed by hand.
PYTHON ?= python3
VENV ?= .venv
BIN = $(VENV)/bin
OUT ?= out

.PHONY: run test docs bench bench-estimate clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# the kernels Cython compiles at install (setup.py): editing one rebuilds its extension module
KERNELS = $(wildcard src/delaykit/*/*.pxd) $(patsubst %.pxd,%.py,$(wildcard src/delaykit/*/*.pxd))

$(VENV)/.installed: $(BIN)/python pyproject.toml setup.py $(KERNELS)
	$(BIN)/pip install -q -e .
	touch $@

# the extras by the installed package's name, not `-e '.[...]'`, which would build every extension a second time
# (the longest step of a fresh clone's set-up): pip finds delaykit installed and adds only what the extras need
$(VENV)/.test-installed: $(VENV)/.installed
	$(BIN)/pip install -q 'delaykit[test,bench,cluster,docs]'
	# Debian's chromium for the test that renders the report page (the test skips, saying why, without it)
	command -v chromium >/dev/null 2>&1 || (timeout 900 sh -c 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium' >/dev/null 2>&1 || echo "chromium could not be installed; the page-rendering test will be skipped")
	touch $@

run: $(VENV)/.installed
	$(BIN)/delaykit reproduce --out $(OUT)/paper
	$(BIN)/delaykit demo --out $(OUT)/demo

# the real-time flights measure timing: they run after the rest, with no other work taking the CPU; they sleep most
# of the time (34 s of CPU in their 4.3 minutes run one at a time), so two run side by side
# the docs are built last, when the tests have compiled and cached the kernels their tutorials run; then the
# tests marked docs read the built site
test: $(VENV)/.test-installed
	$(BIN)/python -m pytest -n 2 -q -m "not realtime and not docs"
	$(BIN)/python -m pytest -n 2 -q -m realtime
	$(MAKE) docs
	$(BIN)/python -m pytest -q -m docs tests/test_docs.py

# the documentation site, into docs/_build/html; warnings are errors, nothing is fetched from the network, and
# the tutorials run only when their code changed (myst-nb's cache in docs/_build/.jupyter_cache)
docs: $(VENV)/.test-installed
	$(BIN)/python -m sphinx -b html -E -W --keep-going -q docs docs/_build/html

bench: $(VENV)/.test-installed
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_general.py
	$(BIN)/python benchmarks/bench_roots.py
	$(BIN)/python benchmarks/bench_poles.py
	$(BIN)/python benchmarks/bench_frequency.py
	$(BIN)/python benchmarks/bench_estimate.py

bench-estimate: $(VENV)/.test-installed
	$(BIN)/python benchmarks/bench_estimate.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .hypothesis docs/_build docs/api docs/jupyter_execute
