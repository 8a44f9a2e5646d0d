"""Whether a class posterior recognises a class: one rule for every place that names one.

The step table's belief (:func:`services.scenario.belief`), the demo's summary, the live view's ``/viz/posterior``
chart (:mod:`shared.foxglove.charts`) and ``foresight log snapshot`` all name the class a posterior recognises; they
used to disagree (0.14 among 8 classes was "(flat)" in the table, "recognised blue_cup" in the snapshot).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["recognised_class"]


def recognised_class(names: Sequence[str], probabilities: Sequence[float] | np.ndarray) -> str:
    """The class a posterior recognises: its most probable one, or ``""`` when the posterior is flat.

    Flat is a top probability under twice the uniform 1/K and under an even chance (with 2 classes the top one
    always has one).

    Args:
        names: ``(K,)`` the class names.
        probabilities: ``(K,)`` p(c | xi), in the order of ``names``.

    Returns:
        The recognised class's name, or ``""`` (flat, or names and probabilities that do not pair up).
    """
    p = np.asarray(probabilities, dtype=float)
    if not len(names) or len(names) != len(p):
        return ""
    k = int(np.argmax(p))
    return str(names[k]) if p[k] >= min(2.0 / len(names), 0.5) else ""
