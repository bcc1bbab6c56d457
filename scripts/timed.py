"""Run commands one after the other and record their wall times (for `make reproduce-all`).

    python scripts/timed.py OUT.json -- "cmd 1" "cmd 2" ...

Stops at the first command that fails (its exit status is returned). OUT.json gets each
command, its wall time in seconds, the total, the machine's core count and load average before
and after, so a timing can be judged later (docs/PERFORMANCE.md quotes it).
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] != "--":
        print(__doc__, file=sys.stderr)
        return 2
    out, commands = Path(argv[0]), argv[2:]
    record = {"cpu_count": os.cpu_count(), "load_before": list(os.getloadavg()), "commands": []}
    start = time.perf_counter()
    status = 0
    for cmd in commands:
        t = time.perf_counter()
        print(f"$ {cmd}", flush=True)
        status = subprocess.call(shlex.split(cmd))
        record["commands"].append({"command": cmd, "seconds": time.perf_counter() - t, "status": status})
        if status:
            break
    record["total_seconds"] = time.perf_counter() - start
    record["load_after"] = list(os.getloadavg())
    record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(record, indent=1), encoding="utf-8")
    print(f"total {record['total_seconds'] / 60:.1f} min; written to {out}")
    return status


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
