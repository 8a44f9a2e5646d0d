"""Reading ``.npz`` files from several threads: one read at a time.

numpy parses each array's header with ``ast.literal_eval``, and CPython 3.11 can fail when threads parse at once
("SystemError: AST constructor recursion depth mismatch", python/cpython#106905). The lock-step harness runs its
services as threads that load their files together (the replayer its demonstration, the predictor its model); a
test loading one library from 8 threads failed on it in CI. Every ``np.load`` of the product reads its arrays while
holding :data:`NPZ_LOCK`.
"""

from __future__ import annotations

import threading

__all__ = ["NPZ_LOCK"]

NPZ_LOCK = threading.Lock()
"""Held while an ``.npz`` file's arrays are read (their headers parsed)."""
