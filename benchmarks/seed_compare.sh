#!/bin/bash
# The first hour's case (Hénon–Heiles [0, 24π], the default march) over 5 seeds with two source
# trees, one after the other on one core, each with its own empty compilation cache; prints each
# seed's true error (max over the grid / state range) and its reference-free estimate.
#
#   bash benchmarks/seed_compare.sh BEFORE/src [AFTER/src] > docs/benchmarks/seed_compare.txt
#
# BEFORE: a git worktree of an earlier commit. Used to check that a change meant to move results
# by rounding only (e.g. γ frozen by a flag in one compiled program) leaves the errors alike.
set -euo pipefail
before=$(cd "$1" && pwd); after=$(cd "${2:-$(dirname "$0")/../src}" && pwd)
python=${PYTHON:-$(dirname "$0")/../.venv/bin/python}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
PYTHONPATH=$after "$python" -c "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))" \
  init "$work/case.toml" --system henon_heiles --T "24*pi" --march > /dev/null
sed -i 's/^seeds = \[0\]/seeds = 5/' "$work/case.toml"
for side in before after; do
  src=$before; [ $side = after ] && src=$after
  PYTHONPATH=$src ATLASNN_CACHE_DIR=$work/cache_$side taskset -c 1 "$python" -c \
    "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))" \
    run "$work/case.toml" --no-progress --out "$work/$side" --figures none > "$work/$side.log"
done
rev() { git -C "$1" rev-parse --short HEAD 2>/dev/null || echo "not a git checkout"; }
echo "# bash benchmarks/seed_compare.sh $*  (before: $before at $(rev "$before"); after: $after at $(rev "$after"))"
"$python" - "$work" <<'PY'
import json, statistics, sys
for side in ("before", "after"):
    runs = json.load(open(f"{sys.argv[1]}/{side}/results.json"))["runs"]
    errs = [r["metrics"]["relative_max"] for r in runs]
    cells = " ".join(f"s{r['seed']}: {r['metrics']['relative_max']:.2e} (est {r['estimate']['relative_max']:.2e}, "
                     f"{r['quality']['status']})" for r in runs)
    print(f"{side}: median {statistics.median(errs):.2e}, max {max(errs):.2e} | {cells}")
PY
