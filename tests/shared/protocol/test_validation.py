"""Value rules on receipt: every message's values against their meaning and the receiver's expectations."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from shared.protocol import (
    ClassPosterior,
    ClockTick,
    DemoMarker,
    Expectations,
    GridSpec,
    HumanKeypoints,
    HumanPose,
    OccupancyGrid,
    Plan,
    ProtocolError,
    RobotSpec,
    RobotState,
    check_values,
)
from shared.protocol import limits as L
from shared.scene import load_scene

NOW = 1.7e9
ROBOT = RobotSpec(("torso", "elbow"), np.array([0.0, -2.0]), np.array([0.3, 0.0]), np.array([0.1, 3.0]))


def realtime(**kw) -> Expectations:
    return Expectations(clock="realtime", now=lambda: NOW, **kw)


def pose(**kw) -> HumanPose:
    f = np.array([0.0, 0.0, 1.0] + [0.1] * 7 + [0.0, 0.5])
    return dataclasses.replace(HumanPose(stamp=NOW, tick=-1, tick_last=True, demo_id=0, index=0, features=f), **kw)


def state(**kw) -> RobotState:
    base = RobotState(stamp=NOW, tick=-1, joint_names=["torso", "elbow"], goal=0, reached=False, holding=False,
                      reason="", q=np.array([0.1, -1.0]), qd=np.array([0.05, 1.0]))
    return dataclasses.replace(base, **kw)


def plan(traj=None, **kw) -> Plan:
    traj = np.array([[[0.1, -1.0], [0.2, -0.5]]], np.float32) if traj is None else traj
    base = Plan(stamp=NOW, tick=-1, step=0, goal_names=["g"], joint_names=["torso", "elbow"], dt=0.1, chosen=0,
                planning_ms=5.0, occupancy_tick=-1, occupancy_index=-1, trajectories=traj,
                cost_smoothness=np.ones(1), cost_obstacle=np.ones(1), cost_human=np.ones(1), cost_total=np.ones(1),
                valid=np.ones(1, bool))
    return dataclasses.replace(base, **kw)


def grid_msg(grid, resolution=None, origin=None, **kw) -> OccupancyGrid:
    g = grid if resolution is None else grid.with_resolution(resolution)
    occ = np.zeros(g.dims, np.float32)
    occ[0, 0, 0] = 1.0
    msg = OccupancyGrid.from_dense(occ, g.origin if origin is None else origin, g.resolution, stamp=NOW, tick=-1,
                                   tick_last=True, demo_id=0, index=0, method="prediction")
    return dataclasses.replace(msg, **kw)


def refused(msg, exp: Expectations, reason: str, text: str = "") -> None:
    with pytest.raises(ProtocolError) as info:
        check_values(msg, exp)
    assert info.value.reason == reason, str(info.value)
    assert text in str(info.value)


# -- stamps and ticks -----------------------------------------------------------------------------

def test_realtime_stamps_within_the_tolerances():
    check_values(pose(stamp=NOW - L.STAMP_PAST_S + 1), realtime())
    check_values(pose(stamp=NOW + L.STAMP_FUTURE_S - 0.1), realtime())
    refused(pose(stamp=NOW + 3600), realtime(), "stamp-future", "HumanPose.stamp")
    refused(pose(stamp=0.0), realtime(), "stamp-past", "old")
    refused(pose(tick=4, stamp=0.8), realtime(), "mismatch", "real-time run")


def test_lockstep_stamps_are_the_ticks_simulated_time():
    exp = Expectations(clock="lockstep", period_s=0.2)
    check_values(state(tick=3, stamp=0.6), exp)
    check_values(state(tick=3, stamp=0.8), exp)
    check_values(state(tick=-1, stamp=0.0), exp)  # the executor's state before step 0
    refused(state(tick=3, stamp=0.81), exp, "stamp-future", "after tick 3")
    refused(state(tick=3, stamp=0.5), exp, "stamp-past", "before tick 3")
    refused(state(tick=3, stamp=NOW), exp, "stamp-future", "no simulated time")
    refused(state(tick=3, stamp=-1.0), exp, "stamp-past")


def test_lockstep_without_the_period_bounds_the_stamp_loosely():
    exp = Expectations(clock="lockstep")
    check_values(state(tick=2, stamp=100.0), exp)
    refused(state(tick=2, stamp=3 * L.MAX_PERIOD_S + 1), exp, "stamp-future")


def test_auto_clock_goes_by_the_messages_tick():
    exp = Expectations(clock="auto", now=lambda: NOW)
    check_values(pose(tick=-1, stamp=NOW), exp)
    check_values(pose(tick=5, stamp=1.0), exp)
    refused(pose(tick=-1, stamp=1.0), exp, "stamp-past")
    # the lock-step state before step 0: refused as 56 years old by the ROS 2 gateway and the live view, every run
    check_values(state(tick=-1, stamp=0.0), exp)
    refused(state(tick=-1, stamp=0.5), exp, "stamp-past")  # nothing else at tick -1 is simulated time
    refused(state(tick=-1, stamp=0.0), realtime(), "stamp-past")  # a real-time receiver still refuses it


def test_ticks_beyond_the_lockstep_clock_are_from_the_future():
    exp = Expectations(clock="lockstep", period_s=0.2, max_tick=lambda: 4)
    check_values(state(tick=4, stamp=0.9), exp)
    refused(state(tick=5, stamp=1.1), exp, "stamp-future", "ahead of the lock-step clock")
    refused(state(tick=L.MAX_TICK + 1, stamp=1.0), exp, "out-of-range")
    refused(state(tick=-2, stamp=0.0), exp, "out-of-range")


def test_clock_tick_stamp_period_and_run_period():
    exp = Expectations(clock="lockstep", period_s=0.2)
    check_values(ClockTick(stamp=7 * 0.2, tick=7, period=0.2), exp)
    refused(ClockTick(stamp=1.5, tick=7, period=0.2), exp, "stamp-future", "tick x period")
    refused(ClockTick(stamp=0.0, tick=0, period=1e-5), Expectations(clock="lockstep"), "out-of-range", "period")
    refused(ClockTick(stamp=0.0, tick=0, period=0.5), exp, "mismatch", "this run's period")


# -- the robot ------------------------------------------------------------------------------------

def test_joint_positions_within_limits_plus_tolerance():
    exp = realtime(robot=ROBOT)
    check_values(state(q=np.array([0.3 + L.JOINT_LIMIT_TOL * 0.9, -1.0])), exp)
    # issue 12: torso q = -15,532 and elbow q = 93,542 were logged as the robot's state
    refused(state(q=np.array([-15532.0, 93542.0])), exp, "joint-limits", "torso = -15532")
    refused(state(q=np.array([0.1, 0.0 + L.JOINT_LIMIT_TOL * 1.1])), exp, "joint-limits", "elbow")


def test_velocities_within_limits():
    exp = realtime(robot=ROBOT)
    check_values(state(qd=np.array([0.1 * (1 + L.VELOCITY_LIMIT_TOL) - 1e-6, -3.0])), exp)
    refused(state(qd=np.array([0.0, 5.5e303])), exp, "velocity", "elbow velocity")
    refused(state(qd=np.array([-0.2, 0.0])), exp, "velocity", "torso")


def test_without_a_robot_model_the_generic_bounds_hold():
    exp = realtime()
    check_values(state(q=np.array([50.0, -50.0]), qd=np.array([10.0, 0.0])), exp)
    refused(state(q=np.array([1e303, 0.0])), exp, "joint-limits")
    refused(state(qd=np.array([0.0, 1e3])), exp, "velocity")


def test_joint_names_must_be_the_receivers():
    refused(state(joint_names=["elbow", "torso"]), realtime(robot=ROBOT), "mismatch", "not this robot's joints")
    refused(plan(joint_names=["a", "b"]), realtime(robot=ROBOT), "mismatch")


def test_plan_waypoints_within_limits_invalid_goals_too():
    """Before, an invalid goal's waypoints went unchecked: at 1e30 they passed, and the live view's scene runs FK
    on all K goals. The planner sends an invalid goal as the robot's start, within the limits."""
    exp = realtime(robot=ROBOT)
    check_values(plan(), exp)
    far = np.array([[[0.1, -1.0], [9.0, -1.0]]], np.float32)
    refused(plan(traj=far), exp, "joint-limits", "trajectories")
    start = np.array([[[0.1, -1.0], [0.1, -1.0]]], np.float32)
    invalid = dict(goal_names=["g", "h"], valid=np.array([True, False]), cost_smoothness=np.array([1, np.inf]),
                   cost_obstacle=np.array([1, np.inf]), cost_human=np.array([1, np.inf]),
                   cost_total=np.array([1, np.inf]))
    check_values(plan(traj=np.concatenate([plan().trajectories, start]), **invalid), exp)
    refused(plan(traj=np.concatenate([plan().trajectories, far]), **invalid), exp, "joint-limits", "trajectories")
    huge = np.full((1, 2, 2), 1e30, np.float32)
    refused(plan(traj=np.concatenate([plan().trajectories, huge]), **invalid), realtime(), "joint-limits",
            "trajectories")
    nan = np.full((1, 2, 2), np.nan, np.float32)  # built in this process: decode never saw it
    refused(plan(traj=np.concatenate([plan().trajectories, nan]), **invalid), realtime(), "non-finite")


def test_plan_scalars_and_costs_bounded():
    exp = realtime()
    refused(plan(dt=1e-6), exp, "out-of-range", "Plan.dt")
    refused(plan(dt=1e3), exp, "out-of-range", "Plan.dt")
    refused(plan(planning_ms=-1.0), exp, "out-of-range", "planning_ms")
    refused(plan(cost_total=np.array([1e303])), exp, "out-of-range", "cost_total")
    for name in ("cost_smoothness", "cost_obstacle", "cost_human", "cost_total"):  # squares and penetrations: >= 0
        refused(plan(**{name: np.array([-5.0])}), exp, "out-of-range", f"{name}: -5 is negative")
    check_values(plan(cost_obstacle=np.array([0.0]), cost_human=np.array([-0.0])), exp)
    refused(plan(step=-1), exp, "out-of-range", "Plan.step")
    refused(state(goal=L.MAX_GOALS), exp, "out-of-range", "RobotState.goal")


# -- the human and the prediction -----------------------------------------------------------------

def test_pose_features_within_their_plausible_range():
    refused(pose(features=np.r_[0.0, 0.0, 1.0, [0.1] * 7, 0.0, 1e303]), realtime(), "out-of-range", "r_elbow_z")
    refused(pose(features=np.r_[0.0, 0.0, 7.0, [0.1] * 7, 0.0, 0.5]), realtime(), "out-of-range", "pelvis_z")
    refused(pose(index=L.MAX_SAMPLES + 1), realtime(), "out-of-range", "index")
    refused(pose(demo_id=-3), realtime(), "out-of-range", "demo_id")


def test_keypoints_within_range_of_the_sensor():
    pts = np.array([[0.1, 0.2, 1.0], [np.nan] * 3, [0.4, 0.2, 1.3]])
    kp = HumanKeypoints(stamp=NOW, tick=-1, frame=3, frame_id="recorder", names=["pelvis", "neck", "r_wrist"],
                        positions=pts)
    check_values(kp, realtime())  # a missing point is no error here (the tracker decides what it needs)
    far = pts.copy()
    far[2] = [1500.0, 0.0, 1.0]  # kilometres away
    with pytest.raises(ProtocolError, match=r"'r_wrist' at \[1500.0, 0.0, 1.0\] m, beyond 20 m") as info:
        check_values(dataclasses.replace(kp, positions=far), realtime())
    assert info.value.reason == "out-of-range"
    with pytest.raises(ProtocolError, match="frame") as info:
        check_values(dataclasses.replace(kp, frame=L.MAX_FRAME + 1), realtime())
    with pytest.raises(ProtocolError, match="stamp") as info:
        check_values(dataclasses.replace(kp, stamp=NOW - 1000.0), realtime())


def test_keypoints_are_real_time_at_every_receiver():
    """Before, a frame of tick 5 (a simulated stamp) passed a receiver on clock "auto" (the view, the ROS 2 gateway);
    only the tracker refused it. Every sensor stamps -1."""
    kp = HumanKeypoints(stamp=1.0, tick=5, frame=3, frame_id="recorder", names=["pelvis"], positions=np.ones((1, 3)))
    for exp in (Expectations(clock="auto"), Expectations(clock="lockstep")):
        refused(kp, exp, "mismatch", "HumanKeypoints.tick: 5: a sensor runs in real time (must be -1)")


def test_marker_counters():
    m = DemoMarker(stamp=NOW, tick=-1, demo_id=0, event="start", true_class=1, class_name="c", n_samples=10)
    check_values(m, realtime())
    refused(dataclasses.replace(m, n_samples=L.MAX_SAMPLES + 1), realtime(), "out-of-range", "n_samples")
    refused(dataclasses.replace(m, true_class=L.MAX_CLASSES), realtime(), "out-of-range", "true_class")


def test_posterior_probabilities_and_class_count():
    p = ClassPosterior(stamp=NOW, tick=-1, demo_id=0, index=0, class_names=["a", "b"],
                       posterior=np.array([0.25, 0.75]), log_likelihood=np.array([-1.0, -np.inf]))
    check_values(p, realtime(n_classes=2))
    refused(p, realtime(n_classes=3), "mismatch", "3")
    above = dataclasses.replace(p, posterior=np.array([1.0 + 5e-7, 0.0]))  # passes the sum check, not [0, 1]
    refused(above, realtime(), "out-of-range", "above 1")
    check_values(dataclasses.replace(p, familiar=False, familiarity=-1e9), realtime())  # the predictor's floor
    refused(dataclasses.replace(p, familiarity=-2e9), realtime(), "out-of-range", "familiarity")


def test_occupancy_geometry_and_the_receivers_grid():
    grid = load_scene().grid
    exp = realtime(grid=GridSpec.from_grid(grid))
    check_values(grid_msg(grid), exp)
    check_values(grid_msg(grid, resolution=0.1), exp)  # a model trained at another resolution
    refused(grid_msg(grid, origin=grid.origin + 0.5), exp, "mismatch", "origin")
    small = grid_msg(grid)
    refused(dataclasses.replace(small, dims=small.dims - 1), exp, "mismatch", "do not cover the scene grid")
    refused(dataclasses.replace(small, resolution=1e-4), realtime(), "out-of-range", "resolution")
    refused(dataclasses.replace(small, origin=np.array([1e6, 0.0, 0.0])), realtime(), "out-of-range", "origin")


def test_a_grid_finer_than_the_receiver_takes_is_refused():
    """The planner takes at most half its scene grid's resolution: a 283-byte grid at 0.01 m cost it 760 MB."""
    grid = load_scene().grid
    exp = realtime(grid=GridSpec.from_grid(grid, grid.resolution / 2))
    check_values(grid_msg(grid, resolution=grid.resolution / 2), exp)
    check_values(grid_msg(grid, resolution=0.1), exp)
    refused(grid_msg(grid, resolution=0.01), exp, "mismatch", "0.01 m is finer than the 0.025 m this receiver takes")
    check_values(grid_msg(grid, resolution=0.01), realtime(grid=GridSpec.from_grid(grid)))  # no floor: any


def test_occupancy_values_are_probabilities_by_construction():
    grid = load_scene().grid
    msg = grid_msg(grid)
    dense = msg.to_dense()
    assert dense.min() >= 0.0 and dense.max() <= 1.0  # uint8 q / 255: an occupancy of 7.0 cannot be sent


def test_unknown_clock_mode_refused():
    with pytest.raises(ValueError, match="clock"):
        Expectations(clock="sometimes")
