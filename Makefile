# The two commands a new user needs: `make demo` and `make test`.
# Both create .venv from pyproject.toml on first use (Python 3.11+ must be on PATH).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
FMU    := build/FourBar.fmu
REALTIME ?= 0
SPEEDUP  ?= 10
# VIEW=0 runs the demo without its live browser view (fourbar-view).
VIEW     ?= 1
# REALTIME=1 runs the demo at wall-clock pace (the paper's live setting).
DEMO_SPEED := $(if $(filter 1,$(REALTIME)),1,$(SPEEDUP))
# What the FMUs are built from: the generated code lives only in the build (and build/generated/).
FMU_SOURCES := build_fmu.py $(wildcard fmu_src/*.py fmu_src/mechanism/*.py fmu_src/mechanism_model/*.py \
               fmu_src/mechanisms/*.toml fmu_src/native/*.[ch] fmu_src/native/fmi3/*.[ch])
MECHANISMS  := $(basename $(notdir $(wildcard fmu_src/mechanisms/*.toml)))

.PHONY: demo test check fmu mechanisms components systems browser tbb benchmarks figures clean help

help:
	@echo "make demo       build the FMU, run Case 2 with orchestrator and monitor, print the verdict"
	@echo "make demo REALTIME=1   the same at wall-clock pace (100 s)"
	@echo "make demo VIEW=0       without the live browser view (fourbar-view)"
	@echo "make test       run the test suite (all of it; what CI runs)"
	@echo "make check      the fast lane: every test not marked slow (about 2 minutes on 2 cores)"
	@echo "make benchmarks measure speed and accuracy (writes docs/benchmarks.md figures to stdout)"
	@echo "make figures    compare the detection/accuracy figures quoted in README and docs with a fresh run"
	@echo "make fmu        build $(FMU) and build/FourBarNative.fmu (when a C compiler exists)"
	@echo "make mechanisms build the FMUs of every mechanism in fmu_src/mechanisms/ into build/"
	@echo "make components build the native FMUs of every component in fmu_src/components/ into build/"
	@echo "make systems    build the SSP file of every system in systems/ into build/ (docs/systems.md)"
	@echo "make browser    install Debian's chromium for the browser tests (make test does it)"
	@echo "make tbb        install Debian's libtbb12, which Ecos (ecospy) needs, for the SSP tests (make test does it)"

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@

$(FMU): $(STAMP) $(FMU_SOURCES)
	$(BIN)/python build_fmu.py --out $(FMU)

fmu: $(FMU)

# Every shipped mechanism's three FMUs (the four-bar's among them: $(FMU) and its Native twins),
# rebuilt when a source changes (the stamp records the build).  BUILD_JOBS builds run at a time
# (each is one process: sympy, then the C compiler), each build's lines printed together when it ends.
MECH_STAMP := build/.mechanisms
BUILD_JOBS ?= 2

$(MECH_STAMP): $(STAMP) $(FMU_SOURCES)
	@printf '%s\n' $(MECHANISMS) | xargs -P $(BUILD_JOBS) -n 1 sh -c \
	  'out=$$($(BIN)/python build_fmu.py --mechanism "$$1" 2>&1); s=$$?; printf "%s\n" "$$out"; exit $$s' sh
	@touch $@

mechanisms: $(MECH_STAMP)

# Every shipped component's native FMUs (build/<Name>Native.fmu and <Name>Native3.fmu, from
# fmu_src/components/*.toml: docs/components.md), rebuilt when a source changes.
COMPONENTS  := $(basename $(notdir $(wildcard fmu_src/components/*.toml)))
COMP_STAMP  := build/.components
COMPONENT_SOURCES := $(FMU_SOURCES) $(wildcard fmu_src/block/*.py fmu_src/components/*.toml fmu_src/native/block/*.[ch])

$(COMP_STAMP): $(STAMP) $(COMPONENT_SOURCES)
	@for c in $(COMPONENTS); do $(BIN)/python build_fmu.py --component "$$c" || exit 1; done
	@touch $@

components: $(COMP_STAMP)

# Every shipped system's SSP file (build/<Name>.ssp, from systems/*.toml: docs/systems.md), built
# once its components and mechanisms are (the tests use build/MotorFourBar.ssp when it is current).
SYSTEMS    := $(basename $(notdir $(wildcard systems/*.toml)))
SYS_STAMP  := build/.systems

$(SYS_STAMP): $(MECH_STAMP) $(COMP_STAMP) $(wildcard systems/*.toml fmu_src/system/*.py)
	@for s in $(SYSTEMS); do $(BIN)/python build_fmu.py --system "$$s" || exit 1; done
	@touch $@

systems: $(SYS_STAMP)

demo: $(FMU)
	$(BIN)/python scripts/demo.py --speedup $(DEMO_SPEED) $(if $(filter 0,$(VIEW)),--no-view,)

# The browser tests of fourbar-view drive Debian's Chromium (Playwright with the system
# browser; its own browser download is not used).  Installed here when missing and run as root.
browser:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "make browser: installing Debian's chromium for the browser tests"; \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1 || \
	    { apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null; } || \
	    echo "make browser: could not install chromium; the browser tests will be skipped"; \
	  else \
	    echo "make browser: no chromium; install Debian's chromium (apt-get install chromium) to run the browser tests"; \
	  fi; }

# Ecos (ecospy, the third SSP master of tests/test_ssp_masters.py) loads Intel TBB's run-time,
# Debian's libtbb12.  Installed here when missing and run as root; else those tests skip.
tbb:
	@ldconfig -p 2>/dev/null | grep -q 'libtbb\.so\.12 ' || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "make tbb: installing Debian's libtbb12 for Ecos (ecospy)"; \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -q libtbb12 >/dev/null 2>&1 || \
	    { apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q libtbb12 >/dev/null; } || \
	    echo "make tbb: could not install libtbb12; the Ecos tests will be skipped"; \
	  else \
	    echo "make tbb: no libtbb12; install Debian's libtbb12 (apt-get install libtbb12) to run the Ecos tests"; \
	  fi; }

# The suite runs on two workers (pytest-xdist; TEST_WORKERS=0 runs it in one process) and
# finds every mechanism's FMUs in build/, built once here rather than once per worker
# ($(MECH_STAMP) first: it builds $(FMU) too, in parallel with the other mechanisms).
TEST_WORKERS ?= 2
test: $(MECH_STAMP) $(COMP_STAMP) $(SYS_STAMP) $(FMU) browser tbb
	$(BIN)/python -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist worksteal)

check: $(FMU)
	$(BIN)/python -m pytest -q -m "not slow" $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist worksteal)

benchmarks: $(FMU)
	$(BIN)/python benchmarks/run_all.py --write docs/benchmarks.md
	$(BIN)/python benchmarks/doc_figures.py --write
	$(BIN)/python benchmarks/robustness.py --write docs/robustness.md

figures: $(FMU)
	$(BIN)/python benchmarks/doc_figures.py --check

clean:
	rm -rf build out .pytest_cache
