"""The native BLAS thread pools of numpy, scipy and scikit-learn: one thread per process unless asked.

Foresight's numpy work is many small products (the 13 x 13 covariances of the class mixtures, a pose's
features against 20 Gaussians, ...). A multi-threaded BLAS gains nothing on such sizes and, on a machine
whose cores are already busy (the four services, two experiment workers, joblib workers), its threads
spin and wait for each other. Measured on this project's 2-core machine with the other cores loaded:
fitting one class mixture of the paper's library (2,500 x 13 samples, 20 Gaussians, 47 EM iterations)
took 7-16 s with OpenBLAS's default 2 threads and 0.6-0.7 s with 1 (the same fit to 3e-13). So every
``foresight`` command, every ``python -m services.X`` and every experiment worker process starts with
one BLAS thread; ``FORESIGHT_BLAS_THREADS`` overrides it (``0``: the libraries' own default).

torch's intra-op threads are separate: the planner sets them (``PlannerConfig.threads``); a process whose
torch work is a robot's forward kinematics for drawing (the executor, ``foresight view``) takes one with
:func:`limit_torch_threads`: on such batches a second thread gains nothing and its OpenMP worker spins.
Measured ad hoc (a replay of a real-time run's 913 messages through ``SceneStream``): 2.16 s of process CPU
with torch's default 2 threads and 1.06 s with 1, in the same 1.1 s of wall time (2026-11-26, 2 cores);
``foresight bench live`` shows the effect on the planning loop (docs/live-view.md).
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

from shared.config import ConfigError

__all__ = ["ENV", "blas_threads", "limit_blas_threads", "limit_torch_threads"]

ENV = "FORESIGHT_BLAS_THREADS"
"""Environment variable: BLAS threads per process (default 1; 0 leaves the libraries' default)."""


def blas_threads() -> int:
    """The BLAS threads per process asked for: ``FORESIGHT_BLAS_THREADS`` or 1.

    Raises:
        ConfigError: If the variable is not an integer >= 0.
    """
    raw = os.environ.get(ENV, "1").strip() or "1"
    try:
        n = int(raw)
    except ValueError:
        raise ConfigError(f"{ENV} must be an integer >= 0 (0: the libraries' default), got {raw!r}") from None
    if n < 0:
        raise ConfigError(f"{ENV} must be an integer >= 0 (0: the libraries' default), got {raw!r}")
    return n


def limit_blas_threads(threads: int | None = None) -> int:
    """Limit the BLAS pools of numpy and scipy in this process for the rest of its life.

    The pools already loaded are limited at once (threadpoolctl); ``OPENBLAS_NUM_THREADS`` (unless set)
    limits the OpenBLAS builds loaded afterwards and in child processes.

    Args:
        threads: Threads per pool (None: :func:`blas_threads`; 0: leave the pools as they are).

    Returns:
        The limit applied (0: none).
    """
    n = blas_threads() if threads is None else int(threads)
    if n > 0:
        # libraries loaded later (scipy's own OpenBLAS comes with scikit-learn) and child processes read the
        # variable when they load; a value the user set is kept
        os.environ.setdefault("OPENBLAS_NUM_THREADS", str(n))
        threadpool_limits(limits=n, user_api="blas")  # the ones already loaded
    return n


def limit_torch_threads(threads: int = 1) -> None:
    """One torch intra-op thread (or ``threads``) in this process: for processes that draw, not plan."""
    import torch

    torch.set_num_threads(int(threads))
