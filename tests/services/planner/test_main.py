"""``foresight planner`` (services/planner/__main__.py): its options come without the planner's torch."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def test_the_planners_help_loads_no_torch() -> None:
    """`foresight planner --help` took 10 s: the config tree (STOMP's and the costs' dataclasses) lived in the modules
    that run them, which import torch and its compiler. The configs live in config.py now; the run imports the rest."""
    code = ("import sys\nfrom services.planner.__main__ import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n"
            "    pass\nprint('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[3]).stdout
    assert "--stomp.iterations" in out and "--cost.w-human" in out and out.strip().splitlines()[-1] == "False", \
        out[-500:]
