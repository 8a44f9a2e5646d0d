"""Skeleton layouts: which of a tracker's or a motion-capture system's points make each of Foresight's points.

A layout is a small table (``shared/data/keypoints/<name>.toml``): each Foresight point
(:data:`shared.keypoints.POINT_NAMES`) is the mean of the layout points listed for it, e.g. the pelvis is the
mean of COCO's two hips. Foresight's own point names are the layout ``foresight`` (identity). Points a
layout does not give are simply unobserved. The table's ``ignored`` list names the layout's other points (a
sensor sends them; Foresight does not use them), so that a name that is neither is an error, not a silent miss.
Its ``order`` lists every point in the sensor's own order (COCO's keypoint ids, MediaPipe's landmark indices):
the order a ROS 2 ``PoseArray`` of that sensor is read in unless ``--ros2-points`` gives another.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from .fit import POINT_NAMES, REQUIRED

__all__ = ["Layout", "load_layout", "LAYOUTS"]

LAYOUTS = ("foresight", "coco17", "mediapipe33", "body25", "plugin_gait")
"""The layouts that ship with Foresight."""


@dataclass(frozen=True)
class Layout:
    """A skeleton layout: Foresight point -> the layout points whose mean it is."""

    name: str
    description: str
    points: dict[str, tuple[str, ...]]
    ignored: tuple[str, ...] = ()
    order: tuple[str, ...] = ()  # the sensor's own order of every point (used and ignored); () where it has none

    @property
    def native_order(self) -> list[str]:
        """The points in the order the sensor sends them: :attr:`order`, else (none is standard) the table's."""
        return list(self.order) or self.table_names

    @property
    def source_names(self) -> list[str]:
        """Every layout point the table uses, in a stable order."""
        return sorted({n for names in self.points.values() for n in names})

    @property
    def table_names(self) -> list[str]:
        """Every layout point the table uses, in the table's order (Foresight's points' order for ``foresight``)."""
        return list(dict.fromkeys(n for names in self.points.values() for n in names))

    def unknown(self, names: list[str]) -> list[str]:
        """The names in ``names`` that are not this layout's points (neither used nor ``ignored``)."""
        known = {*self.source_names, *self.ignored}
        return [n for n in names if n not in known]

    def lacking(self, names: list[str]) -> list[str]:
        """The required points (:data:`~shared.keypoints.fit.REQUIRED`) that frames of ``names`` cannot form."""
        return [p for p in REQUIRED if p not in self.points or not set(self.points[p]) <= set(names)]

    def describe(self, point: str, seen: set[str] | None = None) -> str:
        """Foresight's ``point`` in words, with the layout points it is the mean of where they are other names.

        E.g. ``pelvis (left_hip, right_hip)`` for COCO, ``r_wrist`` for Foresight's own names; given ``seen`` (the
        layout points the frame has), those it lacks too: ``pelvis (left_hip, right_hip: left_hip not seen)``.
        """
        sources = self.points.get(point, ())
        if not sources or sources == (point,):
            return point
        unseen = [] if seen is None else [s for s in sources if s not in seen]
        lacking = f": {', '.join(unseen)} not seen" if unseen else ""
        return f"{point} ({', '.join(sources)}{lacking})"

    def to_model(self, names: list[str], positions: np.ndarray) -> np.ndarray:
        """Positions in the layout's names -> Foresight's points.

        Args:
            names: ``K`` layout point names, the columns of ``positions``.
            positions: ``(..., K, 3)`` (NaN where missing).

        Returns:
            ``(..., J, 3)`` in :data:`POINT_NAMES` order: each the mean of its layout points, NaN when one of them is
            missing or the layout does not give it.
        """
        pos = np.asarray(positions, dtype=np.float64)
        out = np.full((*pos.shape[:-2], len(POINT_NAMES), 3), np.nan)
        index = {n: i for i, n in enumerate(names)}
        for j, point in enumerate(POINT_NAMES):
            sources = self.points.get(point, ())
            if sources and all(s in index for s in sources):
                out[..., j, :] = np.mean(pos[..., [index[s] for s in sources], :], axis=-2)
        return out


def load_layout(name: str) -> Layout:
    """A shipped layout by name (:data:`LAYOUTS`).

    Raises:
        ValueError: An unknown layout, or a table naming a point Foresight does not have, leaving out a required
            one, or whose ``order`` does not list each of its points once.
    """
    if name == "foresight":
        return Layout("foresight", "Foresight's own point names", {p: (p,) for p in POINT_NAMES}, (), POINT_NAMES)
    if name not in LAYOUTS:
        raise ValueError(f"keypoint layout {name!r}: unknown (layouts: {', '.join(LAYOUTS)})")
    data = tomllib.loads((resources.files("shared") / "data" / "keypoints" / f"{name}.toml").read_text())
    points = {k: tuple(v) for k, v in data["points"].items()}
    unknown = set(points) - set(POINT_NAMES)
    if unknown:
        raise ValueError(f"keypoint layout {name}: points {sorted(unknown)} are not the model's {list(POINT_NAMES)}")
    missing = [p for p in REQUIRED if p not in points]
    if missing:
        raise ValueError(f"keypoint layout {name}: gives none of the required {missing}")
    layout = Layout(data["name"], data.get("description", ""), points, tuple(data.get("ignored", ())),
                    tuple(data.get("order", ())))
    every, order = {*layout.source_names, *layout.ignored}, layout.order
    wrong = [f"{what} {names}" for what, names in (
        ("missing", sorted(every - set(order))), ("not its points", sorted(set(order) - every)),
        ("given twice", sorted({n for n in order if order.count(n) > 1}))) if names]
    if order and wrong:  # a PoseArray read in it would put points in the wrong places
        raise ValueError(f"keypoint layout {name}: order must list each of its points once ({'; '.join(wrong)})")
    return layout
