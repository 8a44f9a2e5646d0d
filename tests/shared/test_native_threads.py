"""The BLAS thread limit every Foresight process starts with (shared/native_threads.py)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from shared.config import ConfigError
from shared.native_threads import ENV, blas_threads, limit_blas_threads


def test_default_is_one_thread_and_env_overrides(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV, raising=False)
    assert blas_threads() == 1
    monkeypatch.setenv(ENV, "3")
    assert blas_threads() == 3
    monkeypatch.setenv(ENV, "0")
    assert blas_threads() == 0


@pytest.mark.parametrize("raw", ["two", "-1", "1.5"])
def test_bad_env_value_names_the_variable(monkeypatch: pytest.MonkeyPatch, raw: str) -> None:
    monkeypatch.setenv(ENV, raw)
    with pytest.raises(ConfigError, match=ENV):
        blas_threads()


def test_limit_applies_to_numpy_blas() -> None:
    import numpy  # noqa: F401  (loads the BLAS library)

    with threadpool_limits(limits=None):  # restored on exit
        assert limit_blas_threads(1) == 1
        blas = [p for p in threadpool_info() if p["user_api"] == "blas"]
        assert blas and all(p["num_threads"] == 1 for p in blas)
    assert limit_blas_threads(0) == 0  # 0 leaves the pools alone


def test_foresight_command_starts_with_one_blas_thread() -> None:
    # the dispatcher limits the pools before it runs the command; `library --help` exits at once
    probe = ("import contextlib, io, numpy; from threadpoolctl import threadpool_info; "
             "from tools.foresight import main\n"
             "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
             "    main(['library', '--help'])\n"
             "import scipy.linalg, sklearn.mixture\n"  # scipy's own OpenBLAS loads after the limit
             "print([p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'])")
    env = {k: v for k, v in os.environ.items() if k not in (ENV, "OPENBLAS_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    counts = ast.literal_eval(out.stdout.strip().splitlines()[-1])
    assert len(counts) >= 2 and all(n == 1 for n in counts)
