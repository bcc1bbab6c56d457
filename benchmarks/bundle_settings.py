"""One seed of the built-in oscillator bundle with some training settings changed: the held-out
members' errors window by window (how the bundle settings of docs/FAMILIES.md were compared).

    python -m benchmarks.bundle_settings SEED [key=value ...]

keys: any field of ``BundleTrainConfig`` (windows=12 lm_rounds=8 margin=0.05 ...) and ``width``;
everything else is the built-in config ``oscillator-bundle``. Prints, per window, the median and
worst member's max error up to that window's end (200 held-out members against DOP853 at 1e-12),
and a JSON line with the whole interval's figures.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time

import numpy as np

from atlasnn.evaluation import reference_members
from atlasnn.experiments.config import family_config_path, load_family
from atlasnn.training import train_bundle


def _value(old, text: str):
    if isinstance(old, bool):
        return text.lower() in ("1", "true", "yes")
    return type(old)(text)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print(__doc__)
        return 2
    cfg = load_family(family_config_path("oscillator-bundle"))
    st, system = cfg.bundle, cfg.system.build()
    box, base, width = st.box(system), st.train_config(), st.width
    changes = {}
    for arg in argv[1:]:
        key, _, text = arg.partition("=")
        if key == "width":
            width = int(text)
        elif key in {f.name for f in dataclasses.fields(base)}:
            changes[key] = _value(getattr(base, key), text)
        else:
            raise SystemExit(f"unknown setting {key!r}")
    train = dataclasses.replace(base, **changes)
    seed = int(argv[0])
    z_test, l_test = box.draw(np.random.default_rng(st.test_seed), st.test_members)
    t_test = np.linspace(box.t0, box.T, st.test_times)
    ref = reference_members(system, box, z_test, l_test, t_test)
    start = time.perf_counter()
    trained = train_bundle(system, box, train, scaling=st.model, width=width, depth=st.depth, seed=seed,
                           on_window=lambda k, loss, sec: print(f"window {k}: loss {loss:.3g}, {sec:.0f} s", flush=True))
    err = np.max(np.abs(trained.solution(t_test, z_test, l_test) - ref), axis=-1)  # (members, times)
    for k, edge in enumerate(trained.solution.edges[1:]):
        upto = err[:, t_test <= edge].max(axis=1)
        print(f"up to the end of window {k}: median member {np.median(upto):.2e}, worst {upto.max():.2e}")
    member = err.max(axis=1)
    print(json.dumps({"seed": seed, "settings": argv[1:], "median": float(np.median(member)),
                      "worst": float(member.max()), "p90": float(np.quantile(member, 0.9)),
                      "seconds": time.perf_counter() - start, "retried": trained.retried}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
