"""Fixtures shared by the planner tests: the default scene and the PR2 placed in it (built once per module)."""

from __future__ import annotations

import pytest

from shared.robot import PR2
from shared.scene import Scene, load_scene


@pytest.fixture(scope="module")
def scene() -> Scene:
    return load_scene()


@pytest.fixture(scope="module")
def robot(scene: Scene) -> PR2:
    return PR2.from_scene(scene)
