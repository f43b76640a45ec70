# Two commands a fresh machine with Python 3.11 + pip needs: `make demo` and `make test`.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python

.PHONY: demo test bench lab clean

$(VENV)/.stamp-run: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $@

$(VENV)/.stamp-test: pyproject.toml $(VENV)/.stamp-run
	$(PY) -m pip install --quiet -e ".[test,bench]"
	touch $@

demo: $(VENV)/.stamp-run
	$(VENV)/bin/wingphoto demo data-samples --out results

test: $(VENV)/.stamp-test
	MPLBACKEND=Agg WINGPHOTO_HEADLESS=1 $(PY) -m pytest tests --doctest-modules wingphoto --nbmake notebooks --durations=25

bench: $(VENV)/.stamp-test
	$(PY) benchmarks/calib_bench.py
	$(PY) benchmarks/track_bench.py

# JupyterLab refuses to run as root without --allow-root (containers, many lab workstations);
# LAB_ARGS passes more options, e.g. `make lab LAB_ARGS="--port 8890 --no-browser"`
LAB_ARGS ?=
ALLOW_ROOT := $(if $(filter 0,$(shell id -u 2>/dev/null)),--allow-root,)

lab: $(VENV)/.stamp-run
	$(PY) -m pip install --quiet -e ".[notebooks]"
	$(VENV)/bin/jupyter lab $(ALLOW_ROOT) $(LAB_ARGS) notebooks

clean:
	rm -rf $(VENV) results
