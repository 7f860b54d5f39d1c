# Two commands matter: `make demo` and `make test`. Both create .venv on first use and
# re-install only when pyproject.toml, setup.py or the C plant sources change.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.stamp-install
C_SRC  := $(wildcard firmware_sim/*.c firmware_sim/*.h firmware/core/*.[ch] firmware/targets/host/*.[ch] firmware/targets/plant/*.[ch]) \
          firmware_sim/plant_build.py firmware/targets/host/core_build.py
PKG    := $(wildcard hilbench/*.py)
export QT_QPA_PLATFORM ?= offscreen

.PHONY: all setup demo test bench lint clean

all: test

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip setuptools wheel

$(STAMP): $(BIN)/python pyproject.toml setup.py $(C_SRC) $(PKG)
	$(BIN)/python -m pip install --quiet -e ".[test]"
	$(BIN)/python -c "import hilbench.firmware_sim._plant"   # the C extension is built and importable
	touch $@

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/hilbench demo -o demo-out

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider

bench: $(STAMP)
	$(BIN)/python -m benchmarks

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info firmware_sim/_plant*.so firmware_sim/_plant.c firmware_sim/_fwcore* demo-out
