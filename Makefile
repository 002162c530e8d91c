# mincam_sim: every target sets up its own virtual environment first.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

.PHONY: setup demo test test-all bench lint bad-inputs crosscheck docs clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "mincam_sim needs Python >= 3.11"'
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(PY) -m mincam_sim.render.check
	@touch $(STAMP)

demo: setup
	$(VENV)/bin/mincam-sim -v demo --out out/demo

test: setup
	$(PY) -m pytest -m "not slow" -q

test-all: setup
	$(PY) -m pytest -q

bench: setup
	$(PY) benchmarks/run.py --out benchmarks/results.json

lint: setup
	$(VENV)/bin/ruff check .

# Runs ~80 bad (and a few good) inputs through the CLI in fresh processes and counts the clear one-line errors.
bad-inputs: setup
	$(PY) tests/cli/test_cli_errors.py

# The documentation site with its gallery executed: warnings are errors, cross references nitpicky, no network
# (no intersphinx). Output: docs/_build/html/index.html. One example at a time while writing one:
#   make docs GALLERY=plot_03
DOCS_STAMP = $(VENV)/.docs-installed
GALLERY   ?= /plot_

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[dev,docs]'
	@touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	MPLBACKEND=Agg MINCAM_DOCS_GALLERY_PATTERN='$(GALLERY)' $(PY) -m sphinx -b html -n -W --keep-going docs docs/_build/html
	@echo "docs: docs/_build/html/index.html"

# The wave-optics cross-check against diffractio, in its own environment (diffractio pins numpy < 2).
crosscheck:
	$(PYTHON) -m venv .venv-crosscheck
	.venv-crosscheck/bin/python -m pip install --quiet -e '.[crosscheck]'
	.venv-crosscheck/bin/python -m pytest -q tests/wave/test_wave.py -k diffractio

clean:
	rm -rf $(VENV) .venv-crosscheck out build *.egg-info docs/_build docs/generated docs/gallery docs/sg_execution_times.rst
