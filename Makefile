# garage-mj: `make test` and `make demo` install what they need on a fresh clone.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
TORCH := torch==2.13.0
export MUJOCO_GL ?= egl

.PHONY: install test demo bench lint clean

install: $(STAMP)

# torch first, pinned to the CPU build, so nothing later pulls the multi-GB CUDA wheels.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(TORCH)
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

test: install
	$(PY) -m pytest -q

demo: install
	$(VENV)/bin/garage-mj demo

bench: install
	$(PY) eval/bench_env.py

lint: install
	$(VENV)/bin/ruff check garage_mj tests eval generation

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
