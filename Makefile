# One command per use: `make reproduce` regenerates results/, `make test` checks package and notebooks,
# `make lab` opens the notebooks. Each installs what it needs into .venv from environment.txt first.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PROFILE ?= full
NOTEBOOKS := $(sort $(wildcard notebooks/[0-9][0-9]_*.ipynb))
export PYDEVD_DISABLE_FILE_VALIDATION := 1

.PHONY: install reproduce test lab lint bench clean-cache

install: $(VENV)/.installed

$(VENV)/.installed: environment.txt pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --requirement environment.txt
	$(PY) -m pip install --quiet --no-deps --editable .
	$(PY) -m ipykernel install --sys-prefix --name hipref --display-name "Python (hipref)" >/dev/null
	touch $@

# Execute every notebook with the chosen profile's parameters, in order.
reproduce: install
	mkdir -p results/notebooks
	for nb in $(NOTEBOOKS); do \
		name=$$(basename $$nb .ipynb); \
		$(VENV)/bin/papermill --kernel hipref --cwd notebooks \
			-f params/$(PROFILE)/$$name.yaml $$nb results/notebooks/$$name.ipynb || exit 1; \
	done

test: install
	$(VENV)/bin/ruff check hipref tests notebooks
	$(VENV)/bin/pytest tests
	$(VENV)/bin/pytest --nbval-lax notebooks --nbval-sanitize-with tests/nbval_sanitize.cfg -p no:cacheprovider

lab: install
	$(VENV)/bin/jupyter lab notebooks

bench: install
	$(PY) -m hipref.bench
