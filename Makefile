# Two entry points that work on a fresh machine with only Python 3.10+ and make.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo test bench examples clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	$(PY) -m compileall -q src  # bytecode of the editable sources (not written when PYTHONDONTWRITEBYTECODE is set)
	touch $@

demo: $(VENV)/.installed
	$(VENV)/bin/openfdk demo --force  # a second `make demo` overwrites the first one's results

# one test worker per core, at most 4 (each imports numba and OpenSim); a test file's
# tests stay in one worker, so its module fixtures are built once
test: $(VENV)/.installed
	$(PY) -m pytest -q -n auto --maxprocesses 4 --dist loadfile

bench: $(VENV)/.installed
	$(VENV)/bin/openfdk bench --json

# the generated inputs of the examples (meshes, trials; git-ignored): examples/README.md
examples: $(VENV)/.installed
	$(PY) examples/knee/make_meshes.py
	$(PY) examples/shoulder/make_shoulder.py
	$(PY) examples/studies/make_tmj_inputs.py

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info
