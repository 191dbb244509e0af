# The Makefile is the user interface. Every target depends on the virtual
# environment, which is built from pyproject.toml on first use (and rebuilt
# when pyproject.toml changes).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SCENARIO ?= scenarios/paper.toml
SWEEP ?= studies/example.toml
STRICT ?= 0
export STRICT

.PHONY: all demo synth sim sweep verify report test lint bench clean clean-cache distclean

all: demo

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,native]"
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m verify demo $(SCENARIO)

synth: $(STAMP)
	$(PY) -m synthesis synth $(SCENARIO)

sim: $(STAMP)
	$(PY) -m generated sim $(SCENARIO)

sweep: $(STAMP)
	$(PY) -m sweep run $(SWEEP)

verify: $(STAMP)
	$(PY) -m verify check $(SCENARIO)

report: $(STAMP)
	$(PY) -m verify report $(SCENARIO)

lint: $(STAMP)
	$(VENV)/bin/ruff check core synthesis symbolic generated verify benchmarks sweep tests
	$(VENV)/bin/ruff format --check core synthesis symbolic generated verify benchmarks sweep tests
	$(VENV)/bin/lint-imports

test: lint
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) -m benchmarks.bench
	$(PY) -m benchmarks.steps
	$(PY) -m benchmarks.precision

clean:
	rm -rf out generated/build .pytest_cache

# the build cache lives outside the tree ($HITL_BUILD_DIR or ~/.cache/hitl-formation/build)
clean-cache:
	$(PY) -m generated cache --clear

distclean: clean
	rm -rf $(VENV)
