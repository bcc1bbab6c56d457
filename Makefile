# Set-up and the two main jobs. `make quick` runs a quick reproduction; `make test` runs the tests.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: quick test test-isa reproduce-all reproduce-release reproduce-long long-doc estimate-doc reproduction-doc suite suite-doc solve-runs bench clean-venv

$(BIN)/atlasnn: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

quick: $(BIN)/atlasnn
	$(BIN)/atlasnn reproduce oscillator-short --quick --overwrite

# two workers (pytest-xdist), a test file per worker at a time: 5.7 min on the 2-core machine
# against 9.6 min in one process (CONTRIBUTING.md); TEST_WORKERS=0 runs them in this process
TEST_WORKERS ?= 2
PYTEST = $(BIN)/python -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile)
test: $(BIN)/atlasnn
	$(PYTEST)

# The suite again with XLA's code limited to older x86 instruction sets, as on a CPU without
# AVX-512 (AVX2) or without AVX (SSE4_2): results move in the last bits with the instruction set,
# and through a training further, so a test fitted to one machine's digits fails here. XLA_FLAGS
# is part of JAX's compilation-cache key: each set's programs are kept apart in the one cache
# (tests/test_compile_cache_isa.py). `make test-isa ISAS=AVX2` runs one set.
ISAS ?= AVX2 SSE4_2
test-isa: $(BIN)/atlasnn
	@for isa in $(ISAS); do echo "== XLA_FLAGS=--xla_cpu_max_isa=$$isa"; \
	  XLA_FLAGS="--xla_cpu_max_isa=$$isa" $(PYTEST) || exit 1; done

# The paper's four experiments at full settings, 5 seeds, both profiles (docs/REPRODUCTION.md).
# `make reproduce-all` is the paper profile; its wall time goes to runs/paper/timing.json.
SEEDS ?= 5
JOBS ?= 2
PAPER := oscillator-short oscillator-transfer henon-heiles-short henon-heiles-transfer

reproduce-all: $(BIN)/atlasnn
	$(BIN)/python scripts/timed.py runs/paper/timing.json -- $(foreach e,$(PAPER),\
	  "$(BIN)/atlasnn reproduce $(e) --seeds $(SEEDS) --jobs $(JOBS) --out runs/paper/$(e) --overwrite --no-progress")

reproduce-release: $(BIN)/atlasnn
	$(BIN)/python scripts/timed.py runs/release/timing.json -- $(foreach e,$(PAPER),\
	  "$(BIN)/atlasnn reproduce $(e) --profile release --seeds $(SEEDS) --jobs $(JOBS) --out runs/release/$(e) --overwrite --no-progress")

# The two long-time experiments (time-marching against the paper's transfer and the classical
# integrators), 5 seeds; `make long-doc` rewrites only their parts of docs/REPRODUCTION*.md.
LONG := oscillator-long henon-heiles-long

reproduce-long: $(BIN)/atlasnn
	$(BIN)/python scripts/timed.py runs/paper/long-timing.json -- $(foreach e,$(LONG),\
	  "$(BIN)/atlasnn reproduce $(e) --seeds $(SEEDS) --jobs $(JOBS) --out runs/paper/$(e) --overwrite --no-progress")

long-doc: $(BIN)/atlasnn
	$(BIN)/python scripts/reproduction_doc.py --long-only $(foreach e,$(LONG),runs/paper/$(e))

# The estimate and verdict against the true error over the paper's experiments (after
# reproduce-all and reproduce-long): only that section of docs/REPRODUCTION.md.
estimate-doc: $(BIN)/atlasnn
	$(BIN)/python scripts/reproduction_doc.py --estimate-only $(foreach e,$(PAPER) $(LONG),runs/paper/$(e))

reproduction-doc: $(BIN)/atlasnn
	$(BIN)/python scripts/reproduction_doc.py $(foreach e,$(PAPER),runs/paper/$(e) runs/release/$(e)) runs/paper/oscillator-long runs/paper/henon-heiles-long

# The hard-problem suite (docs/SUITE.md): every problem, direct training, adaptive and fixed-window
# time-marching, 5 seeds; then its tables into docs/.
suite: $(BIN)/atlasnn
	$(BIN)/python scripts/timed.py runs/suite-hard.timing.json -- \
	  "$(BIN)/atlasnn suite hard --seeds $(SEEDS) --jobs $(JOBS) --out runs/suite-hard --no-progress"

suite-doc: $(BIN)/atlasnn
	$(BIN)/python scripts/suite_doc.py runs/suite-hard

# The float64 collocation solver (docs/SOLVER.md) on every hard problem and both long experiments,
# five seeds each, nothing trained (--profile solve); records and summary into docs/runs/suite-solve/.
solve-runs: $(BIN)/atlasnn
	$(BIN)/atlasnn suite hard --profile solve --out runs/suite-solve --overwrite --no-progress
	for e in henon-heiles-long oscillator-long; do \
	  $(BIN)/atlasnn reproduce $$e --profile solve --out runs/suite-solve/$$e/solve --overwrite --no-progress || exit 1; done
	$(BIN)/python scripts/solve_doc.py runs/suite-solve docs/runs/suite-solve

bench: $(BIN)/atlasnn
	$(BIN)/pip install -q 'torch==2.13.0'
	$(BIN)/python -m benchmarks.throughput

clean-venv:
	rm -rf $(VENV)
