# bayes_amb: everything a fresh clone needs, from nothing.
#   make demo   - create .venv (Python >= 3.12), install, compile the numba kernels once
#                 (python -m bayes_amb.warmup), run the end-to-end demo
#   make test   - same set-up, then the default test suite (2 processes, pytest-xdist)
#   make bench  - the benchmarks (ratios against a baseline run side by side)
#   make docs   - the documentation site in site/ (mkdocs --strict; not part of make test)
# BLAS threads: the tool limits them itself (bayes_amb/threads.py; BAYES_AMB_THREADS=N).
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench docs lint clean venv

venv: $(STAMP)

$(STAMP): pyproject.toml tools/find-python.sh
	@set -e; \
	if [ ! -x $(PY) ] || ! $(PY) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' 2>/dev/null; then \
	  base=$$(tools/find-python.sh); \
	  echo "creating $(VENV) with $$base"; \
	  rm -rf $(VENV); "$$base" -m venv $(VENV); \
	fi
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	$(PY) -m bayes_amb.warmup
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/bayes-amb demo

test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadgroup

bench: $(STAMP)
	$(VENV)/bin/bayes-amb bench

docs: $(STAMP)
	$(PY) -m pip install --quiet -e '.[docs]'
	$(PY) tools/readme_to_index.py
	JUPYTER_PATH=$(CURDIR)/tools/jupyter $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(PY) -m ruff check bayes_amb tests benchmarks studies

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info site docs/index.md
