"""A body tracker's keypoints in the 3D scene, between reaches too (``/viz/keypoints``).

The tracker publishes the human's poses during reaches (and a few of the person seen at rest, once per track),
so the body on ``/viz/human`` shows a reach and stays grey between reaches. The sensor's own points show the person
all the time: each frame's points as small spheres, placed in the scene as the poses are
(:func:`shared.human.placement.place_points`: the rigid motion that takes the newest demonstration's first pelvis
pose to the scene's human), so that they meet the body where a reach is drawn. Before the first demonstration (the
person seen at rest, unless the tracker's ``announce_rest`` is off) no placement is known and nothing is drawn.
Each frame's spheres live :data:`LIFETIME_S`: when the sensor stops or the person leaves, they go.
"""

from __future__ import annotations

import numpy as np
from foxglove.messages import SceneEntity, SceneUpdate

from shared.human.placement import place_points
from shared.protocol import HumanKeypoints
from shared.scene import Scene

from .primitives import duration, spheres, timestamp
from .scene import WORLD_FRAME

__all__ = ["LIFETIME_S", "KEYPOINT_RGBA", "RADIUS_M", "keypoints_update"]

LIFETIME_S = 0.5
"""How long a frame's spheres stay without a newer frame, at least (drawn at most ``viz_rate_hz``: the executor's log 5
a second, the view 10); at a slower rate, two drawing periods (:func:`keypoints_update`'s ``period_s``)."""
KEYPOINT_RGBA = (0.95, 0.95, 0.35, 0.9)
RADIUS_M = 0.03


def keypoints_update(msg: HumanKeypoints, reference: np.ndarray | None, scene: Scene, stamp: float,
                     period_s: float = 0.0) -> SceneUpdate | None:
    """The frame's seen points as spheres in the scene, or None (no placement yet, or no point seen).

    Args:
        msg: The sensor's frame (recorder's frame, metres; NaN where lost).
        reference: ``(12,)`` the newest demonstration's first pose (:meth:`SceneBuilder.placement_reference`).
        scene: The scene the human is placed in.
        stamp: The entity's time (s).
        period_s: The drawing period (the stream's ``viz_period_s``): the spheres live two of them if that is longer
            than :data:`LIFETIME_S` (at ``--viz-rate-hz 1`` they blinked: half a second on, half off).
    """
    if reference is None:
        return None
    pos = np.asarray(msg.positions, dtype=np.float64).reshape(-1, 3)
    seen = pos[np.all(np.isfinite(pos), axis=1)]
    if not len(seen):
        return None
    return SceneUpdate(entities=[SceneEntity(
        timestamp=timestamp(stamp), frame_id=WORLD_FRAME, id="human/keypoints",
        lifetime=duration(max(LIFETIME_S, 2 * period_s)),
        spheres=spheres(place_points(seen, reference, scene), RADIUS_M, KEYPOINT_RGBA))])
