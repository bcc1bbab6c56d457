# Set-up and the two main jobs. `make quick` runs a quick reproduction; `make test-all` runs the tests.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: quick test test-long test-all test-slow test-isa docs reproduce-all reproduce-release reproduce-long long-doc estimate-doc reproduction-doc suite suite-doc solve-runs bench clean-venv

$(BIN)/atlasnn: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

quick: $(BIN)/atlasnn
	$(BIN)/atlasnn reproduce oscillator-short --quick --overwrite

# Two tiers, each in two workers (pytest-xdist, a test file per worker at a time; TEST_WORKERS=0
# runs them in this process). `make test` is the quick tier, everything but the tests marked long
# or slow; `make test-long` the tests marked long (5 s or more each here). CI runs both in one run
# (`make test-all`); the times are in CONTRIBUTING.md.
TEST_WORKERS ?= 2
PYTEST = $(BIN)/python -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder)
test: $(BIN)/atlasnn
	$(PYTEST) -m "not slow and not long"

test-long: $(BIN)/atlasnn
	$(PYTEST) -m "long and not slow"

# both tiers in one run (what CI runs: one run balances its files over the workers better than two)
test-all: $(BIN)/atlasnn
	$(PYTEST) -m "not slow"

# the tests marked slow (half a minute or more each; CI leaves them out to stay under 20 minutes)
test-slow: $(BIN)/atlasnn
	$(PYTEST) -m slow

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

# The Gauss collocation (docs/SOLVER.md) on every hard problem and both long experiments,
# nothing trained (--profile solve: deterministic, one seed); records and summary into docs/runs/suite-solve/
solve-runs: $(BIN)/atlasnn
	$(BIN)/atlasnn suite hard --profile solve --out runs/suite-solve --overwrite --no-progress
	for e in henon-heiles-long oscillator-long; do \
	  $(BIN)/atlasnn reproduce $$e --profile solve --out runs/suite-solve/$$e/solve --overwrite --no-progress || exit 1; done
	$(BIN)/python scripts/solve_doc.py runs/suite-solve docs/runs/suite-solve

# The documentation site (mkdocs.yml): docs/ and the API reference from the docstrings, into site/;
# --strict makes every warning (a broken link or anchor, a docstring that does not render) an error.
# the site into site/, then the docs test's site check (a strict build with no Sphinx role shown as
# text), which `make test` skips where mkdocs is not installed
docs: $(BIN)/atlasnn
	$(BIN)/pip install -q -e '.[docs]'
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict
	$(BIN)/python -m pytest -q tests/test_docs.py::test_the_site_builds_strict

# Every benchmark record the docs cite, rerun, and the docs' generated tables rewritten from them
# (benchmarks/README.md: the instruments, their questions and records). Hours on the 2-core machine;
# one at a time: `make bench BENCH="throughput compile_once"`. The GPU records: scripts/gpu_check.sh.
ONE_CORE := taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
BENCH ?= throughput seed_batch device_accuracy time_to_accuracy compile_once cold_start chain_cost rerun_drift \
	estimate_effectivity window_optimisers bundle_eval bundle_cost flowmap_estimate flowmap_gauss_newton \
	inverse_starts inverse_collocation_untuned inverse_noise solver_workprecision solver_suite solver_batch \
	solver_first_run gauss_stages gauss_roundoff outer_solar energy_long step_modes diffrax_gauss shooting_solver \
	nls_pde fput_recurrence everyday fixed_cost gauss_orders gauss_scaling time_transform rebound_anchor \
	gauss_gradients learned_h sine_gordon_pde
BR := docs/benchmarks

bench: $(BIN)/atlasnn
	$(BIN)/pip install -q -e '.[bench]'
	$(MAKE) $(addprefix bench-,$(BENCH))

bench-nls_pde:
	taskset -c 1 $(BIN)/python -m benchmarks.nls_pde --points 256 512 1024 --T 5 --out $(BR)/nls_pde.json --figure $(BR)/nls_pde.png
	taskset -c 1 $(BIN)/python -m benchmarks.nls_pde --scaling 64 128 256 512 1024 2048 4096 --out $(BR)/nls_pde_scaling.json \
	  --figure $(BR)/nls_pde_scaling.png
bench-fput_recurrence:
	$(BIN)/python examples/fput_recurrence.py --T 20000 --out docs/runs/fput/recurrence.json --figure docs/runs/fput/recurrence.png
bench-throughput:
	taskset -c 0 $(BIN)/python -m benchmarks.throughput --rounds 3 --torch-threads 1 --out $(BR)/throughput.json --doc docs/PERFORMANCE.md
bench-seed_batch:
	taskset -c 0 $(BIN)/python -m benchmarks.seed_batch --out $(BR)/seed_batch_one_core.json
bench-device_accuracy:
	$(BIN)/python -m benchmarks.device_accuracy --seeds 64 --epochs 20000 --out $(BR)/device_accuracy_cpu.json
	$(BIN)/python -m benchmarks.device_accuracy --table $(BR)/device_accuracy_cpu.json $(BR)/gpu/device_accuracy_gpu.json \
	  $(BR)/gpu/device_accuracy_gpu_tf32.json $(BR)/gpu/device_accuracy_gpu_full.json --doc docs/PERFORMANCE.md
bench-time_to_accuracy:
	taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false $(BIN)/python -m benchmarks.time_to_accuracy --seeds 3 --doc docs/PERFORMANCE.md
bench-compile_once:
	$(BIN)/python -m benchmarks.compile_once --experiment oscillator-long --doc docs/PERFORMANCE.md
bench-cold_start:
	$(BIN)/python -m benchmarks.cold_start --repeat 3 --out $(BR)/cold_start.json
bench-chain_cost:
	$(BIN)/python -m benchmarks.chain_cost --particles 16 64 --doc docs/PERFORMANCE.md
bench-rerun_drift:
	$(BIN)/python benchmarks/rerun_drift.py
bench-estimate_effectivity:
	$(BIN)/python -m benchmarks.estimate_effectivity --doc docs/ESTIMATE.md
bench-window_optimisers:
	$(BIN)/python -m benchmarks.window_optimisers --doc docs/ESTIMATE.md
bench-bundle_eval:
	$(BIN)/python -m benchmarks.bundle_eval
bench-bundle_cost:
	$(ONE_CORE) $(BIN)/python -m benchmarks.bundle_cost --run docs/runs/families/oscillator-bundle \
	  --out $(BR)/bundle_cost.json --figure docs/figures/bundle_cost
	$(ONE_CORE) $(BIN)/python -m benchmarks.bundle_cost --run docs/runs/families/oscillator-bundle-float64 \
	  --out $(BR)/bundle_cost_float64.json --figure docs/figures/bundle_cost_float64
bench-flowmap_estimate:
	$(ONE_CORE) $(BIN)/python -m benchmarks.flowmap_estimate
bench-flowmap_gauss_newton:
	taskset -c 0 $(BIN)/python -m benchmarks.flowmap_gauss_newton
bench-inverse_starts:
	$(BIN)/python -m benchmarks.inverse_starts --out $(BR)/inverse_starts.json
	$(BIN)/python -m benchmarks.inverse_starts --column collocation --out $(BR)/inverse_starts.json
	$(BIN)/python -m benchmarks.inverse_starts --column segments --out $(BR)/inverse_starts.json
bench-inverse_collocation_untuned:
	$(BIN)/python -m benchmarks.inverse_collocation_untuned --out $(BR)/inverse_collocation_untuned.json
bench-inverse_noise:
	taskset -c 0 $(BIN)/python -m benchmarks.inverse_noise --seeds 3
bench-solver_workprecision:
	$(BIN)/python -m benchmarks.solver_workprecision
bench-solver_suite:
	$(BIN)/python -m benchmarks.solver_suite --out docs/runs/solver/suite.json
bench-solver_batch bench-solver_first_run bench-step_modes bench-gauss_stages bench-gauss_roundoff bench-shooting_solver: bench-%:
	$(BIN)/python -m benchmarks.$* --out $(BR)/$*.json
bench-everyday bench-fixed_cost: bench-%:
	taskset -c 1 $(BIN)/python -m benchmarks.$* --out $(BR)/$*.json
bench-gauss_orders bench-gauss_scaling bench-rebound_anchor: bench-%:
	$(BIN)/python -m benchmarks.$*
bench-time_transform:
	taskset -c 1 $(BIN)/python -m benchmarks.time_transform --out $(BR)/time_transform.json
bench-gauss_gradients:
	$(BIN)/python -m benchmarks.gauss_gradients --out $(BR)/gauss_gradients.json
bench-learned_h:
	$(BIN)/python -m benchmarks.learned_h --systems two-body double-pendulum pendulum --sigmas 0.0 0.01 0.05 \
		--steps 1000 --rate 0.003 --seed 0 --out $(BR)/learned_h.json --figure $(BR)/learned_h.png
bench-sine_gordon_pde:
	taskset -c 1 $(BIN)/python -m benchmarks.sine_gordon_pde --points 256 --T 10 --out $(BR)/sine_gordon_pde.json \
		--figure $(BR)/sine_gordon_pde.png
bench-outer_solar:
	ATLASNN_CACHE_DIR=off $(BIN)/python -m benchmarks.outer_solar --out $(BR)/outer_solar.json
bench-energy_long:
	$(BIN)/python -m benchmarks.energy_long
bench-diffrax_gauss:
	taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false $(BIN)/python -m benchmarks.diffrax_gauss --repeats 11
# the tables of docs/SOLVER.md and docs/CHOOSING.md from the solver records above
solver-doc: $(BIN)/atlasnn
	$(BIN)/python scripts/solver_doc.py

clean-venv:
	rm -rf $(VENV)
