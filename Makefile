# Two entry points for a fresh machine: `make demo` and `make test`. Both create .venv and install.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Nothing here renders: without this, dm_control tries GLFW and warns about DISPLAY.
export MUJOCO_GL ?= disable

.PHONY: demo test lint bench clean

$(STAMP): setup.cfg pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

# A small real benchmark run: two presets (+ the task-aware reference) on the sparse task, one seed.
demo: $(STAMP)
	$(PY) evaluation/run.py --agents oracle oracle_rh --tasks cheetah_dir_sparse --seeds 0 \
		--frames 300000 --eval-every 60000 --out runs/demo --force

test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) bench/suite_speed.py

clean:
	rm -rf $(VENV) build *.egg-info
