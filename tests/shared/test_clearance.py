"""The robot-to-body clearance (``shared.clearance``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from shared.clearance import body_clearance, segment_distance
from shared.human import HumanModel


class OneSphere:
    """A robot of one collision sphere of radius ``r`` whose centre is ``q[:3]``."""

    def __init__(self, r: float) -> None:
        self.lower = torch.zeros(3, dtype=torch.float64)
        self.sphere_radii = torch.tensor([r], dtype=torch.float64)

    def sphere_centers(self, q: torch.Tensor) -> torch.Tensor:
        return q[..., None, :3]


def test_clearance_of_a_sphere_at_a_known_distance_from_the_body() -> None:
    human = HumanModel()
    posture = np.zeros(12)
    ends, radii = human.capsules(posture)
    # the capsule farthest out along -y is the hand/forearm: place the sphere above its middle
    k = int(np.argmin(ends[:, :, 1].mean(axis=1)))
    mid = ends[k].mean(axis=0)
    r = 0.03
    for d in (0.02, 0.10, 0.25):
        centre = mid + np.array([0.0, 0.0, radii[k] + r + d])
        c = body_clearance(OneSphere(r), centre[None], posture[None], human)
        assert c[0] == pytest.approx(d, abs=1e-6)
    inside = mid + np.array([0.0, 0.0, radii[k] - 0.01])
    assert body_clearance(OneSphere(r), inside[None], posture[None], human)[0] < 0


def test_a_batch_of_instants_equals_each_instant_alone() -> None:
    rng = np.random.default_rng(0)
    human = HumanModel()
    postures = np.zeros((5, 12))
    postures[:, 0] = rng.uniform(-0.2, 0.2, 5)
    q = rng.uniform(-0.5, 0.5, (5, 3)) + [0.0, -0.4, 1.0]
    batched = body_clearance(OneSphere(0.05), q, postures, human)
    looped = [body_clearance(OneSphere(0.05), q[i:i + 1], postures[i:i + 1], human)[0] for i in range(5)]
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-12)


def test_segment_distance_beyond_the_ends_is_to_the_nearer_end() -> None:
    a, b = np.zeros(3), np.array([1.0, 0.0, 0.0])
    p = np.array([[0.5, 2.0, 0.0], [-3.0, 0.0, 0.0], [1.0, 0.0, 4.0]])
    np.testing.assert_allclose(segment_distance(p, a, b), [2.0, 3.0, 4.0])
