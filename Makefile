# Two commands matter: `make demo` and `make test`. Both create .venv on first use and
# re-install only when pyproject.toml, setup.py or the C plant sources change.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.stamp-install
C_SRC  := $(wildcard firmware_sim/engine/*.c firmware_sim/engine/*.h firmware/core/*.[ch] firmware/targets/host/*.[ch] firmware/targets/plant/*.[ch]) \
          firmware_sim/engine/plant_build.py firmware/targets/host/core_build.py
PKG    := $(wildcard hilbench/*.py)
export QT_QPA_PLATFORM ?= offscreen
# Compiled modules are cached in __pycache__ (git-ignored) even where the environment says not to
# (PYTHONDONTWRITEBYTECODE): every CLI, device and worker process the tests start would compile hilbench again
# (0.84 s against 0.55 s for `hilbench --help`), and pytest would rewrite every test module in each part.
unexport PYTHONDONTWRITEBYTECODE

.PHONY: all setup demo test bench lint clean toolchain firmware chromium

all: test

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip setuptools wheel

$(STAMP): $(BIN)/python pyproject.toml setup.py $(C_SRC) $(PKG)
	$(BIN)/python -m pip install --quiet -e ".[test,docs-query]"
	$(BIN)/python -c "import hilbench.firmware_sim.engine._plant, hilbench.firmware_sim.devices._fwcore"  # C extensions built
	touch $@

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/hilbench demo -o demo-out --overwrite

# The emulated Cortex-M target (tests marked `target`) needs a cross compiler, newlib and QEMU. They are
# installed from Debian packages when missing and we may (root with apt-get); otherwise those tests skip
# with one line naming the package.
ARM_PACKAGES := gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm

toolchain:
	@missing=""; \
	command -v arm-none-eabi-gcc >/dev/null 2>&1 || missing="$$missing gcc-arm-none-eabi"; \
	[ -d /usr/lib/arm-none-eabi/newlib ] || missing="$$missing libnewlib-arm-none-eabi"; \
	command -v qemu-system-arm >/dev/null 2>&1 || missing="$$missing qemu-system-arm"; \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing$$missing"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing) \
	    >/dev/null || echo "could not install$$missing: the target tests will skip"; \
	else echo "not root: the target tests will skip (apt-get install$$missing)"; fi

# The campaign page's test loads it in headless Chromium (Debian package chromium), installed like the toolchain.
chromium:
	@command -v chromium >/dev/null 2>&1 && exit 0; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing chromium"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium) \
	    >/dev/null || echo "could not install chromium: the campaign page test will skip"; \
	else echo "not root: the campaign page test will skip (apt-get install chromium)"; fi

firmware: $(STAMP) toolchain
	$(MAKE) -C firmware qemu nucleo PYTHON=$(abspath $(BIN)/python)

# Tests without a realtime device run on every core; those with one (marked `realtime` by tests/conftest.py)
# then run one at a time on a quiet machine. Both parts always run; the worse exit code is make's.
# Each part lists its 15 slowest tests, so that growth of the suite's time (aim: under 10 min) is seen where it happens.
# A test that hangs fails after TEST_TIMEOUT seconds (pytest-timeout) instead of holding the whole run.
# One BLAS thread per test process: two workers each running OpenBLAS's two spinning threads on two cores made
# the numeric tests 2-3x slower (a stationary drift campaign: 10 s alone, 20 s in the parallel part).
TEST_TIMEOUT ?= 300
test: export OMP_NUM_THREADS = 1
test: export OPENBLAS_NUM_THREADS = 1
test: export MKL_NUM_THREADS = 1
test: $(STAMP) toolchain chromium
	@$(BIN)/python -m pytest -q -p no:cacheprovider --durations=15 --timeout=$(TEST_TIMEOUT) -m "not realtime" -n auto --dist loadfile; a=$$?; \
	$(BIN)/python -m pytest -q -p no:cacheprovider --durations=15 --timeout=$(TEST_TIMEOUT) -m realtime; b=$$?; \
	exit $$(( a > b ? a : b ))

bench: $(STAMP)
	$(BIN)/python -m benchmarks

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info firmware_sim/engine/_plant*.so firmware_sim/engine/_plant.c firmware_sim/devices/_fwcore* firmware/build demo-out
