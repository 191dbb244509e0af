# The Makefile is the user interface. Every target depends on the virtual
# environment, which is built from pyproject.toml on first use (and rebuilt
# when pyproject.toml changes).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SCENARIO ?= scenarios/paper.toml
SWEEP ?= studies/example.toml
SEARCH ?= studies/search-faults.toml
STRICT ?= 0
export STRICT
# SET='KEY=VALUE;KEY=VALUE' (';' separates overrides; values may hold commas) and
# VARIANT=NAME reach synth, sim, verify, report and demo as --set ... --variant NAME
SET ?=
VARIANT ?=
export SET VARIANT
KNOBS = set -f; set --; IFS=';'; for s in $$SET; do case "$$s" in *[!\ ]*) set -- "$$@" --set "$$s";; esac; done; unset IFS; \
	if [ -n "$$VARIANT" ]; then set -- "$$@" --variant "$$VARIANT"; fi;
KNOB_GOALS := all demo design synth sim verify report venv
ifeq ($(MAKELEVEL),0)
# a misspelt knob on the command line is refused, not dropped
MISSPELT := set=SET Set=SET SETS=SET sets=SET OVERRIDE=SET OVERRIDES=SET override=SET \
	overrides=SET variant=VARIANT Variant=VARIANT VARIANTS=VARIANT variants=VARIANT \
	scenario=SCENARIO SCENARIOS=SCENARIO sweep=SWEEP search=SEARCH strict=STRICT port=PORT
$(foreach p,$(MISSPELT),$(if $(filter command line,$(origin $(firstword $(subst =, ,$(p))))),\
	$(error $(firstword $(subst =, ,$(p)))= is not a variable of this Makefile: use $(lastword $(subst =, ,$(p)))=)))
ifneq ($(SET)$(VARIANT),)
ifneq ($(filter-out $(KNOB_GOALS),$(MAKECMDGOALS)),)
$(error SET=/VARIANT= are taken by design, synth, sim, verify, report and demo, not by $(filter-out $(KNOB_GOALS),$(MAKECMDGOALS)))
endif
endif
endif

.PHONY: all demo design synth sim sweep search console chromium verify report check test lint bench clean clean-cache distclean

all: demo

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[dev,native,console]"
	$(MAKE) chromium
	touch $(STAMP)

venv: $(STAMP)

# a scenario with a [design] table runs its designed gains (designed first if needed)
demo: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m design demo $(SCENARIO) "$$@"

# gains designed for the guarantees: out/<name>-designed/{gains.json,design.md} (docs/synthesis.md)
design: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m design run $(if $(filter command line environment,$(origin SCENARIO)),$(SCENARIO),scenarios/paper-design.toml) "$$@"

synth: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m synthesis synth $(SCENARIO) "$$@"

sim: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m generated sim $(SCENARIO) "$$@"

sweep: $(STAMP)
	$(PY) -m sweep run $(SWEEP)

# worst-case search of a search file's requirements over its study space (docs/search.md)
search: $(STAMP)
	$(PY) -m search run $(SEARCH)

# the live operator console on http://127.0.0.1:$(PORT)/ (docs/console.md)
PORT ?= 8765
console: $(STAMP)
	$(PY) -m console serve $(SCENARIO) --port $(PORT)

# the browser the console's test drives (Debian's chromium, through Playwright); where it
# cannot be installed (no apt, not root) the test is skipped and says why
chromium:
	@if [ ! -x /usr/bin/chromium ] && command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
		apt-get install -y -q chromium >/dev/null || (apt-get update -q >/dev/null && apt-get install -y -q chromium >/dev/null) \
		|| echo "chromium could not be installed: the console's browser test will be skipped"; fi

verify: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m verify check $(SCENARIO) "$$@"

report: $(STAMP)
	@$(KNOBS) set -x; $(PY) -m verify report $(SCENARIO) "$$@"

lint: $(STAMP)
	$(VENV)/bin/ruff check core synthesis symbolic generated verify design benchmarks sweep search console tests
	$(VENV)/bin/ruff format --check core synthesis symbolic generated verify design benchmarks sweep search console tests
	$(VENV)/bin/lint-imports

# the quick tier for the edit loop: ruff, the import contract and the tests not marked slow
# (tests/conftest.py marks the modules that compile generated C or integrate whole runs)
check: lint
	$(PY) -m pytest -m "not slow"

# one test file per worker, a worker per core (module fixtures are built once); the 25
# slowest tests are listed at the end
test: lint chromium
	$(PY) -m pytest -n auto --dist loadfile --durations=25

bench: $(STAMP)
	$(PY) -m benchmarks.bench
	$(PY) -m benchmarks.steps
	$(PY) -m benchmarks.precision
	$(PY) -m benchmarks.study
	$(PY) -m benchmarks.remedies
	$(PY) -m design run scenarios/paper-design.toml  # studies/links.toml runs the designed gains
	$(PY) -m benchmarks.links
	$(PY) -m benchmarks.agents
	$(PY) -m sweep run studies/topologies.toml || [ $$? -eq 1 ]  # 1: samples failed (in its report)
	$(PY) -m benchmarks.search

clean:
	rm -rf out generated/build .pytest_cache

# the build cache lives outside the tree ($HITL_BUILD_DIR or ~/.cache/hitl-formation/build)
clean-cache:
	$(PY) -m generated cache --clear

distclean: clean
	rm -rf $(VENV)
