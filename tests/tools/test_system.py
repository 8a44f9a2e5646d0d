"""tools.system: a process's memory from /proc."""

from __future__ import annotations

import math
import os

from tools.system import peak_rss_mb, rss_mb


def test_memory_of_a_live_process_and_of_none() -> None:
    assert peak_rss_mb(os.getpid()) >= rss_mb(os.getpid()) > 10.0
    gone = 2**22 + 17  # no such process
    assert math.isnan(peak_rss_mb(gone)) and rss_mb(gone) == 0.0
