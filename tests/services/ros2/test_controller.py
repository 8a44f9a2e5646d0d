"""SimulatedController: a joint_trajectory_controller's motion (start from where it is, replace, hold; no points:
refused)."""

from __future__ import annotations

import numpy as np

from services.ros2.controller import SimulatedController


def test_follows_from_where_it_is_and_holds_the_last_point() -> None:
    arm = SimulatedController(np.zeros(2))
    arm.command(0.0, [1], np.array([[1.0], [2.0]]), np.array([1.0, 2.0]))  # joint 0 not named: kept
    np.testing.assert_allclose(arm.position(0.5), [0.0, 0.5])
    np.testing.assert_allclose(arm.position(1.5), [0.0, 1.5])
    np.testing.assert_allclose(arm.position(9.0), [0.0, 2.0])
    arm.advance(0.5)
    np.testing.assert_allclose(arm.qd, [0.0, 1.0])  # the mean velocity over the interval
    arm.advance(0.5)
    np.testing.assert_allclose(arm.qd, [0.0, 0.0])


def test_a_new_trajectory_replaces_the_old_one_from_the_present_position() -> None:
    arm = SimulatedController(np.zeros(1))
    arm.command(0.0, [0], np.array([[1.0]]), np.array([1.0]))
    arm.advance(0.5)
    arm.command(0.5, [0], np.array([[0.0]]), np.array([0.5]))
    np.testing.assert_allclose(arm.position(0.75), [0.25])  # from 0.5 back to 0 in 0.5 s
    assert arm.received == 2


def test_no_points_is_refused_as_the_real_controller_does_and_a_point_due_now_is_where_the_arm_is() -> None:
    """ros2_controllers' JointTrajectoryController refuses an empty trajectory and goes on: it is no hold."""
    arm = SimulatedController(np.zeros(1))
    arm.command(0.0, [0], np.array([[1.0]]), np.array([1.0]))
    arm.advance(0.5)
    arm.command(0.5, [0], np.zeros((0, 1)), np.zeros(0))
    np.testing.assert_allclose(arm.position(3.0), [1.0])
    assert arm.received == 1
    arm.command(0.5, [0], np.array([[0.5]]), np.array([1e-3]))  # the executor's hold: one point where the arm is
    np.testing.assert_allclose(arm.position(3.0), [0.5])
    arm.command(0.5, [0], np.array([[0.2], [0.4]]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(arm.position(0.5), [0.2])
    np.testing.assert_allclose(arm.position(1.0), [0.3])

