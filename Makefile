# garage-mj: `make test` and `make demo` install what they need on a fresh clone: the demo only the
# package in .venv; the tests also their tools, the ASAM checkers (.venv-qc) and Blender (.venv-blender).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# pip compiles what it installs to bytecode one file at a time (torch alone: about 35 s); the installs skip that and
# each virtualenv is compiled once installed, on every core (a file that does not compile is left for Python to
# report on import). The bytecode matters: where PYTHONDONTWRITEBYTECODE is set, Python keeps none of its own, and
# every test process would compile what it imports again (torch and the rest: 5 s more per process).
PIP_INSTALL := -m pip install -q --no-compile
COMPILE := -m compileall -q -q -j 0
MAIN_STAMP := $(VENV)/.installed-main
STAMP := $(VENV)/.installed
TORCH := torch==2.13.0
# The ASAM OpenDRIVE checker pins numpy < 2, so it gets its own virtualenv (garage_mj/export/validate.py),
# shared with the ASAM OpenSCENARIO XML checker (the .xosc tests).
QC_VENV := .venv-qc
QC_STAMP := $(QC_VENV)/.installed
QC_OPENDRIVE := asam-qc-opendrive==1.0.0
QC_OPENSCENARIO := asam-qc-openscenarioxml==1.0.0
# Blender as a Python module reads garage.fbx back in the FBX tests (garage_mj/export/validate.py), an
# independent reader of what Assimp writes. bpy 5.0 needs CPython 3.11 and pins numpy < 2, so it gets its own
# virtualenv: a 375 MB download, 970 MB installed, about 20 s.
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed
BPY := bpy==5.0.1
export MUJOCO_GL ?= egl

.PHONY: install browser test test-all demo bench lint docs clean

# the three virtualenvs and the browser are independent: `make test` builds them side by side (downloads overlap)
install:
	@$(MAKE) --no-print-directory -j3 $(STAMP) $(QC_STAMP) $(BLENDER_STAMP)

# The virtualenv with pip up to date and torch first, pinned to the CPU build, so nothing later pulls the
# multi-GB CUDA wheels.
define venv_with_torch
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) $(PIP_INSTALL) --upgrade pip
	$(PY) $(PIP_INSTALL) $(TORCH)
endef

# What the demo runs: torch, then the package.
$(MAIN_STAMP): pyproject.toml
	$(venv_with_torch)
	$(PY) $(PIP_INSTALL) -e .
	$(PY) $(COMPILE) $(VENV)/lib garage_mj || true
	touch $(MAIN_STAMP)

# What the tests add, in the same install (one editable build): the test and docs tools, Ray core (--backend
# ray; tests/test_ray_backend.py) and CARLA's OpenDRIVE parser for the XODR tests (34 MB wheel, CPython
# 3.10-3.12, Linux/Windows); where no carla wheel fits, the rest without it.
$(STAMP): pyproject.toml
	$(venv_with_torch)
	$(PY) $(PIP_INSTALL) -e '.[dev,ray,carla]' || { echo "warning: no carla wheel for this Python/platform; the XODR CARLA test will fail with a hint"; $(PY) $(PIP_INSTALL) -e '.[dev,ray]'; }
	$(PY) $(COMPILE) $(VENV)/lib garage_mj || true
	touch $(MAIN_STAMP) $(STAMP)

# Depends on the Makefile so a new checker pin reaches an existing .venv-qc (pip skips what is installed).
$(QC_STAMP): Makefile
	test -x $(QC_VENV)/bin/python || $(PYTHON) -m venv $(QC_VENV)
	$(QC_VENV)/bin/python $(PIP_INSTALL) $(QC_OPENDRIVE) $(QC_OPENSCENARIO)
	$(QC_VENV)/bin/python $(COMPILE) $(QC_VENV)/lib || true
	touch $(QC_STAMP)

$(BLENDER_STAMP): Makefile
	test -x $(BLENDER_VENV)/bin/python || $(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python $(PIP_INSTALL) $(BPY) || echo "warning: no $(BPY) wheel for this Python (CPython 3.11 only); the FBX read-back tests will fail with a hint"
	$(BLENDER_VENV)/bin/python $(COMPILE) $(BLENDER_VENV)/lib || true
	touch $(BLENDER_STAMP)

# Headless Chromium + ChromeDriver (Debian packages) for the report test; installed once when missing.
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || { \
	  echo "installing Debian packages chromium chromium-driver (report test)"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq chromium chromium-driver >/dev/null; }

# make test leaves out the tests marked slow (tests/conftest.py SLOW) to stay under 10 minutes on 2 cores;
# make test-all runs every test. Both run the tests on TEST_WORKERS processes (pytest-xdist, worksteal: a process
# that runs out of tests takes some of the other's, so one long file does not hold up the end; measured 410 s of
# pytest against 426 s with one file per process): TEST_WORKERS=0 runs them in this process.
TEST_WORKERS ?= 2
test:
	@$(MAKE) --no-print-directory -j4 $(STAMP) $(QC_STAMP) $(BLENDER_STAMP) browser
	$(PY) -m pytest -q -m "not slow" -n $(TEST_WORKERS) --dist worksteal

test-all:
	@$(MAKE) --no-print-directory -j4 $(STAMP) $(QC_STAMP) $(BLENDER_STAMP) browser
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist worksteal

demo: $(MAIN_STAMP)
	$(VENV)/bin/garage-mj demo

bench: $(MAIN_STAMP)
	$(PY) eval/bench_env.py

# The documentation site (mkdocs.yml, sources in docs/) into site/; tests/test_docs.py builds it with --strict.
# results.md, performance.md and README.md's results table are rendered (eval/render_pages.py): a stale one
# stops the build.
docs: $(STAMP)
	$(PY) eval/render_pages.py --check
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

lint: $(STAMP)
	$(VENV)/bin/ruff check garage_mj tests eval generation pytest_garage_mj.py docs/pytest_example docs/parking_example

clean:
	rm -rf $(VENV) $(QC_VENV) $(BLENDER_VENV) build site *.egg-info .pytest_cache
