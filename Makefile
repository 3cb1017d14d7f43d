# One command per use: `make reproduce` regenerates results/, `make test` checks package and notebooks,
# `make lab` opens the notebooks. Each installs what it needs into .venv from environment.txt first.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PROFILE ?= full
NOTEBOOKS := $(sort $(wildcard notebooks/[0-9][0-9]_*.ipynb))
export PYDEVD_DISABLE_FILE_VALIDATION := 1
# numpy and OpenBLAS compute with their AVX2 kernels on every CPU, so rows do not depend on whether the
# machine has AVX-512 (hipref/numerics.py; torch and MKL are pinned by the package itself).
export NPY_DISABLE_CPU_FEATURES := X86_V4 AVX512_ICL AVX512_SPR
export OPENBLAS_CORETYPE := Haswell

# Only the full profile regenerates the committed results/; any other writes to results/<profile>/, which
# git ignores.
ifeq ($(PROFILE),full)
RESULTS := results
else
RESULTS := results/$(PROFILE)
endif

# Prefix of a command whose results must not touch the checkout: HIPREF_RESULTS_DIR points at a fresh
# temporary directory, removed when the command ends, fails or is interrupted.
TEMP_RESULTS = tmp=$$(mktemp -d -t hipref-results.XXXXXX) && trap 'rm -rf "$$tmp"' EXIT && \
	trap 'exit 130' INT TERM && HIPREF_RESULTS_DIR=$$tmp

# $(call execute,PROFILE,RESULTS DIR,OUTPUT DIR,JOBS[,--committed]): run every notebook through
# hipref/run_notebook.py with the profile's parameters, JOBS at a time, its results written to RESULTS DIR and
# the executed notebook to OUTPUT DIR, replaced only once it has run through and with no absolute path in its
# outputs; --committed also removes papermill's injected-parameters cell. The first failure stops the rest.
define execute
	mkdir -p $(3)
	printf '%s\n' $(NOTEBOOKS) | xargs -P $(4) -I NOTEBOOK sh -c '\
		name=$$(basename NOTEBOOK .ipynb); \
		HIPREF_RESULTS_DIR=$(abspath $(2)) $(PY) -m hipref.run_notebook $(5) \
			-f params/$(1)/$$name.yaml NOTEBOOK $(3)/$$name.ipynb || exit 255'
endef

# Notebooks at a time. The quick profile's are short and spend much of their time starting kernels and
# workers, so two run side by side (as nbval runs them); the full profile's run in order, each reusing the
# learning clips and evaluation episodes the ones before it built rather than building them at the same time.
ifeq ($(PROFILE),full)
JOBS := 1
else
JOBS := 2
endif

.PHONY: help install reproduce notebooks test lint typecheck pytest nbval lab teach bench readme readme-check

# A bare `make` lists the targets; every other target installs first what it needs.
.DEFAULT_GOAL := help

# Times measured on the 2-core machine of the README's "Time" section.
help:
	@echo 'make reproduce PROFILE=quick  every notebook at the quick profile into results/quick/ (about 4 min)'
	@echo 'make reproduce                every notebook at the paper scale: rewrites the committed results/ (25-35 min)'
	@echo 'make notebooks                re-executes notebooks/ in place at the quick profile (about 4 min)'
	@echo 'make test                     lint, typecheck, pytest and nbval; writes no tracked file (about 7 min)'
	@echo 'make lint                     ruff on the package, tests and notebooks (seconds)'
	@echo 'make typecheck                mypy on hipref/ (under a minute)'
	@echo 'make pytest                   the tests of tests/ on every core (about 2 min)'
	@echo 'make nbval                    checks the outputs of the committed notebooks (about 4 min)'
	@echo 'make lab                      JupyterLab on notebooks/'
	@echo 'make teach PARTICIPANT=P01    notebook 09 for participant P01 with Voila, no code: http://127.0.0.1:8866/ (PORT=, DOMAIN=, TRUE_PARAMETER=, QUERIES=)'
	@echo 'make bench                    the benchmarks of hipref/bench/, printing their figures'
	@echo 'make readme                   the findings of README.md rewritten from the committed results/ (seconds)'
	@echo 'make readme-check             checks the findings of README.md against the committed results/ (seconds)'
	@echo 'make install                  .venv from environment.txt (about 7 min, 2.1 GB with the CPU build of torch)'
	@echo 'Any target but help installs first. NOTEBOOKS=notebooks/NN_x.ipynb limits reproduce, notebooks and nbval.'

install: $(VENV)/.installed

$(VENV)/.installed: environment.txt pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --requirement environment.txt
	$(PY) -m pip install --quiet --no-deps --editable .
	$(PY) -m ipykernel install --sys-prefix --name hipref --display-name "Python (hipref)" >/dev/null
	touch $@

# Execute every notebook with the chosen profile's parameters (JOBS at a time) into $(RESULTS)/notebooks/.
reproduce: install
	$(call execute,$(PROFILE),$(RESULTS),$(RESULTS)/notebooks,$(JOBS))

# Re-execute the committed notebooks in place at the quick profile (what nbval checks), without papermill's
# injected-parameters cell: the parameters cell's defaults are the quick profile. Results to results/quick/.
notebooks: install
	$(call execute,quick,results/quick,notebooks,2,--committed)

# In this order; `make nbval NOTEBOOKS=notebooks/06_noise_estimation.ipynb` checks a single notebook.
test: lint typecheck pytest nbval

lint: install
	$(VENV)/bin/ruff check hipref tests notebooks

# mypy over hipref/ (its settings in pyproject.toml); its cache in .mypy_cache, which git ignores.
typecheck: install
	$(VENV)/bin/mypy

# On every core: the slowest tests wait on kernels, browsers and worker processes, and overlap well. Whole
# files to a worker (each module fixture built once), the files of the tests marked slow first
# (tests/conftest.py).
pytest: install
	$(TEMP_RESULTS) $(VENV)/bin/pytest --numprocesses=auto --dist=loadfile --no-loadscope-reorder tests

# Two notebooks at a time, each in its own kernel (a notebook's cells stay in order on one worker): their
# kernels start, import and plot while the other's sweep computes. The kernels listen on sockets of their own
# (tests/nbval_kernel.py), so two starting together never take the same port. The longest notebooks first,
# by the time papermill recorded in each (tests/nbval_kernel.py).
nbval: install
	$(TEMP_RESULTS) $(PY) -m pytest -p tests.nbval_kernel --numprocesses=2 --dist=loadfile --no-loadscope-reorder \
		--nbval-lax \
		$(NOTEBOOKS) --nbval-sanitize-with tests/nbval_sanitize.cfg -p no:cacheprovider

lab: install
	$(VENV)/bin/jupyter lab --ServerApp.allow_root=True notebooks

# Participant mode: notebook 09's participant cells served with Voila (hipref/teach/make_teach.py); the
# conditions' query rules in the order the participant meets them, QUERIES each, catch trials every CATCH_EVERY
# queries, in DOMAIN's world with TRUE_PARAMETER (empty: three quarters up the range, 0.8 m or 17 kg).
# Each is set on make's command line; the shell's own variables of these names (PORT and DOMAIN are common)
# are not read. The values reach the command through the environment as given ($(value)), so an id is never
# read as make's or the shell's code. The command replaces the recipe's shell (exec) and ends with make, so a
# kill of make stops the server too.
SHELL_PARTICIPANT := $(if $(filter environment,$(origin PARTICIPANT)),$(value PARTICIPANT))
# A setting make teach does not know (a typo, QUERY=4) is refused rather than silently ignored.
TEACH_SETTINGS := PARTICIPANT CONDITIONS CATCH_EVERY PORT DOMAIN QUERIES TRUE_PARAMETER PYTHON MUJOCO_GL
TEACH_UNKNOWN = $(filter-out $(TEACH_SETTINGS),$(foreach v,$(.VARIABLES),$(if $(filter command line,$(origin $(v))),$(v))))
PARTICIPANT =
CONDITIONS = uniform information_gain
CATCH_EVERY = 4
PORT = 8866
DOMAIN = wiping
QUERIES = 12
TRUE_PARAMETER =
teach: override export PARTICIPANT := $(value PARTICIPANT)
teach: override export CONDITIONS := $(value CONDITIONS)
teach: override export CATCH_EVERY := $(value CATCH_EVERY)
teach: override export PORT := $(value PORT)
teach: override export DOMAIN := $(value DOMAIN)
teach: override export QUERIES := $(value QUERIES)
teach: override export TRUE_PARAMETER := $(value TRUE_PARAMETER)
teach: override export SHELL_PARTICIPANT := $(value SHELL_PARTICIPANT)
teach: install
	@test -z '$(TEACH_UNKNOWN)' || { echo 'make teach: unknown setting(s) $(TEACH_UNKNOWN); make teach takes $(TEACH_SETTINGS)' >&2; exit 2; }
	@test -n "$$PARTICIPANT" || { test -z "$$SHELL_PARTICIPANT" || \
		printf 'make teach: PARTICIPANT=%s is set in the shell, which make teach does not read\n' "$$SHELL_PARTICIPANT" >&2; \
		echo 'make teach PARTICIPANT=<id>: the participant id is missing' >&2; exit 2; }
	exec $(PY) -m hipref.teach.make_teach "$$PARTICIPANT" --conditions $$CONDITIONS --catch-every "$$CATCH_EVERY" \
		--domain "$$DOMAIN" --queries "$$QUERIES" $${TRUE_PARAMETER:+--true-parameter "$$TRUE_PARAMETER"} --port "$$PORT"

bench: install
	$(PY) -m hipref.bench.physics
	$(PY) -m hipref.bench.sweep
	$(PY) -m hipref.bench.clips
	$(PY) -m hipref.bench.teach
	$(PY) -m hipref.bench.startup

# The README's findings (every number and verdict) from the committed results/; `make readme-check` only compares.
readme: install
	$(PY) -m hipref.readme

readme-check: install
	$(PY) -m hipref.readme --check
