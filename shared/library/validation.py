"""The rules every demonstration passes before it is used, whatever file it comes from.

A block of rows (one demonstration) is malformed when it has fewer than :data:`MIN_SAMPLES` samples,
a non-finite or subnormal value, a feature identically zero over the block (a dead channel) or, for
a feature set with a mapping to the human model, a feature outside its plausible range. The CSV
reader adds the rules of its format (column count, index column, truncation); the npz reader applies
these to every stored demonstration.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from shared.feature_sets import mapping_for

from .motions import FEATURE_NAMES

__all__ = ["MIN_SAMPLES", "validate_block", "line_ranges"]

MIN_SAMPLES = 10
"""Shortest demonstration accepted (samples)."""

_TINY = np.finfo(np.float64).tiny  # smallest normal float64; non-zero values below it are garbage


def line_ranges(lines: Iterable[int]) -> str:
    """Line numbers ``[5, 6, 7, 9]`` -> ``"5-7, 9"`` (at most four ranges, then ``...``)."""
    parts: list[str] = []
    start = prev = None
    for n in lines:
        if start is None:
            start = prev = n
        elif n == prev + 1:
            prev = n
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = n
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    return ", ".join(parts[:4] + (["..."] if len(parts) > 4 else []))


def _ranges(mask: np.ndarray) -> str:
    """``[F, F, T, T, F, T]`` -> ``"2-3, 5"`` (0-based positions of True, compressed)."""
    return line_ranges(np.flatnonzero(mask).tolist())


def validate_block(features: np.ndarray, feature_names: tuple[str, ...] = FEATURE_NAMES,
                   lines: Sequence[int] | None = None) -> list[str]:
    """Check one demonstration's features against the library rules.

    Args:
        features: ``(T, F)`` feature rows of one block.
        feature_names: The F feature names; the plausible ranges are checked where they have a mapping.
        lines: ``(T,)`` the file line of each row (a CSV): the messages name the line of a value they quote.

    Returns:
        Reasons the block is malformed (empty when it is valid). Sample positions are 0-based.
    """
    names = tuple(feature_names)
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != len(names):
        return [f"has shape {f.shape}, expected (T, {len(names)})"]
    reasons: list[str] = []
    if f.shape[0] < MIN_SAMPLES:
        reasons.append(f"has {f.shape[0]} samples, fewer than the minimum {MIN_SAMPLES}")
    finite = np.isfinite(f)
    if not finite.all():
        bad = ~finite
        cols = [names[j] for j in np.flatnonzero(bad.any(axis=0))]
        reasons.append(f"non-finite values in {', '.join(cols)} at samples {_ranges(bad.any(axis=1))}")
    g = np.where(finite, f, 0.0)
    subnormal = (g != 0) & (np.abs(g) < _TINY)
    dead = np.all((g == 0) | subnormal, axis=0) & finite.all(axis=0)
    if dead.any():
        reasons.append(f"dead channel(s): {', '.join(names[j] for j in np.flatnonzero(dead))} zero or subnormal "
                       f"in all {f.shape[0]} samples")
    def at(row: int) -> str:
        return f" at line {lines[row]}" if lines is not None else ""

    live_sub = subnormal & ~dead[None, :]
    if live_sub.any():
        cols = [names[j] for j in np.flatnonzero(live_sub.any(axis=0))]
        reasons.append(f"subnormal (garbage) values in {', '.join(cols)} (first{at(int(np.argmax(live_sub.any(1))))})"
                       if lines is not None else f"subnormal (garbage) values in {', '.join(cols)}")
    mapping = mapping_for(names)
    if mapping is None:  # no plausible ranges known for an unmapped feature set
        return reasons
    low = np.array([mapping.plausible_ranges[n][0] for n in names])
    high = np.array([mapping.plausible_ranges[n][1] for n in names])
    out = finite & ((f < low) | (f > high))
    for j in np.flatnonzero(out.any(axis=0)):
        name = names[j]
        lo, hi = mapping.plausible_ranges[name]
        rows = np.flatnonzero(out[:, j])
        col = f[rows, j]
        k = int(np.argmax(np.maximum(lo - col, col - hi)))
        reasons.append(f"{name} outside its plausible range [{lo:g}, {hi:g}] {mapping.units[j]} in "
                       f"{len(rows)} samples (e.g. {col[k]:g}{at(int(rows[k]))})")
    return reasons
