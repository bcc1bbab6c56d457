# Set-up and the two main jobs. `make quick` runs a quick reproduction; `make test` runs the tests.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: quick test reproduce-all bench clean-venv

$(BIN)/atlasnn: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

quick: $(BIN)/atlasnn
	$(BIN)/atlasnn reproduce oscillator-short --quick --overwrite

test: $(BIN)/atlasnn
	$(BIN)/python -m pytest -q

# The paper's four experiments at full settings (see docs/REPRODUCTION.md for seeds and timings).
reproduce-all: $(BIN)/atlasnn
	for e in oscillator-short oscillator-transfer henon-heiles-short henon-heiles-transfer; do \
	  $(BIN)/atlasnn reproduce $$e --seeds 3 --out runs/$$e --overwrite || exit 1; done

bench: $(BIN)/atlasnn
	$(BIN)/pip install -q 'torch==2.13.0'
	$(BIN)/python -m benchmarks.throughput

clean-venv:
	rm -rf $(VENV)
