"""The human: a kinematic model of the paper's 12 posture features, its body, and its place in a scene.

* :mod:`shared.human.model`: :class:`HumanModel` (the HERAKLES joint tree driven by the 12
  features, capsule body volumes, surface points);
* :mod:`shared.human.placement`: :func:`place_in_scene`, :class:`StreamPlacement`, :func:`voxelize`,
  :func:`reach_points`.

The names below are the public ones of both (``from shared.human import HumanModel, place_in_scene``).
"""

from .model import N_FEATURES, HumanError, HumanModel, Segment, check_features
from .placement import StreamPlacement, place_in_scene, reach_points, voxelize

__all__ = ["N_FEATURES", "HumanError", "Segment", "HumanModel", "check_features", "place_in_scene",
           "StreamPlacement", "voxelize", "reach_points"]
