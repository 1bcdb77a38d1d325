# make setup: the venv, every pinned dependency, glocal_interfaces built from
# msg_schemas/, glocal_ros installed with the `ros2 run` layout. Idempotent:
# each step is skipped when its inputs did not change.
# make test: setup, then the whole suite.   make run: setup, then the demo.

PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip --disable-pip-version-check
STAMPS := $(VENV)/.stamps

.PHONY: setup test run clean
.DEFAULT_GOAL := setup

setup: $(STAMPS)/interfaces $(STAMPS)/package

# COLCON_IGNORE: the ROS wheels put package.xml files under .venv/share,
# which a colcon build from the repo root must not take for packages.
$(PY):
	$(PYTHON) -m venv $(VENV)
	touch $(VENV)/COLCON_IGNORE

$(STAMPS)/deps: $(wildcard requirements*.txt) constraints.txt | $(PY)
	$(PIP) install -q pip==25.3 setuptools==79.0.1 wheel==0.45.1
	$(PIP) install -q -r requirements.txt -c constraints.txt
	@mkdir -p $(STAMPS) && touch $@

# The build script skips each interface package whose sources did not change.
$(STAMPS)/interfaces: $(STAMPS)/deps $(shell find msg_schemas tools/tf2_msgs -type f) tools/build_interfaces.py
	$(PY) tools/build_interfaces.py --build $(VENV)/build
	@touch $@

# Editable install for the Python packages, plus setup.py's data_files (the
# ament index marker, package.xml, lib/glocal_ros executables, assets) copied
# into the venv prefix, which an editable install leaves out.
$(STAMPS)/package: $(STAMPS)/deps setup.py setup.cfg package.xml $(wildcard bin/*) $(wildcard launch/*) $(shell find assets -type f 2>/dev/null)
	$(PIP) install -q --no-deps --no-build-isolation -e .
	$(PY) setup.py -q install_data -d $(VENV) 2>/dev/null
	@touch $@

test: setup
	$(PY) -m pytest

run: setup
	$(VENV)/bin/glocal-ros launch --preset demo --out runs/demo

clean:
	rm -rf build install log $(VENV) *.egg-info
