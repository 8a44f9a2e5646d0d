"""The number of CPUs this process may use: its affinity, capped by its cgroup's CPU quota (stdlib only).

``make test`` sizes pytest-xdist's workers with it (``python tools/cpus.py --max 4``), before the virtual
environment exists. A container limited with ``--cpus 2`` on a 16-core host has an affinity of 16 and
a quota of 2: the quota is what it can use.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

__all__ = ["usable_cpus", "quota_cpus"]


def quota_cpus(root: Path = Path("/sys/fs/cgroup")) -> float | None:
    """The cgroup's CPU quota in CPUs (cgroup v2 ``cpu.max``, else v1 ``cpu.cfs_quota_us``), None if unlimited.

    Args:
        root: The cgroup file system's mount point (tests give a folder of their own).
    """
    try:
        quota, period = (root / "cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        quota_us = int((root / "cpu" / "cpu.cfs_quota_us").read_text())
        period_us = int((root / "cpu" / "cpu.cfs_period_us").read_text())
        return quota_us / period_us if quota_us > 0 and period_us > 0 else None
    except (OSError, ValueError):
        return None


def usable_cpus(root: Path = Path("/sys/fs/cgroup")) -> int:
    """CPUs this process may use: its affinity (else ``os.cpu_count()``), at most its quota rounded up, at least 1."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    quota = quota_cpus(root)
    return max(1, min(n, math.ceil(quota)) if quota else n)


def main(argv: list[str] | None = None) -> int:
    """Print :func:`usable_cpus`, capped by ``--max``."""
    p = argparse.ArgumentParser(prog="python tools/cpus.py", description=__doc__.split("\n")[0])
    p.add_argument("--max", type=int, default=0, help="print at most this many (0: no cap)")
    args = p.parse_args(argv)
    if args.max < 0:  # it printed every CPU for --max -3, as for no cap
        p.error(f"--max: must be 0 (no cap) or more, got {args.max}")
    n = usable_cpus()
    print(min(n, args.max) if args.max > 0 else n)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
