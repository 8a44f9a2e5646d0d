"""Planner core (Algorithm 1) on a toy planar robot, and on the PR2 with its real state cost."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest
import torch

from services.planner.core import GoalSet, Planner, PlannerConfig, PlannerError, PlannerInputError
from services.planner.costs import CostConfig
from services.planner.multigoal import init_straight_lines
from services.planner.stomp import StompConfig
from shared.config import ConfigError
from shared.protocol import OccupancyGrid
from shared.scene import load_scene


class ToyRobot:
    """Two prismatic joints moving a point in the plane z = 1 m of the scene."""

    joint_names = ["x", "y"]
    lower = torch.tensor([-0.5, -1.0])
    upper = torch.tensor([1.2, 0.3])
    velocity_limits = torch.tensor([1.0, 1.0])


class ToyCost:
    """(K, R, T, 2) -> (K, R, T, 2): no obstacle; the occupancy at (x, y, 1.0) as the human term."""

    terms = ("obstacle", "human")

    def set_occupancy(self, occupancy: torch.Tensor, origin: np.ndarray, resolution: float) -> None:
        self.occ, self.origin, self.res = occupancy, torch.as_tensor(origin, dtype=torch.float32), resolution

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        xyz = torch.cat([q, torch.ones_like(q[..., :1])], -1)
        idx = ((xyz - self.origin) / self.res).floor().long()
        dims = torch.tensor(self.occ.shape)
        idx = torch.minimum(torch.maximum(idx, torch.zeros(3, dtype=torch.long)), dims - 1)
        human = 10 * self.occ[idx[..., 0], idx[..., 1], idx[..., 2]]
        return torch.stack([torch.zeros_like(human), human], -1)


def blob_grid(scene, center=(0.5, -0.2, 1.0), sigma=0.12) -> np.ndarray:
    """Dense (nx, ny, nz) gaussian occupancy blob on the scene grid."""
    c = scene.grid.centers()
    return np.exp(-((c - np.asarray(center)) ** 2).sum(-1) / (2 * sigma**2)).astype(np.float32)


def toy_planner(scene, **cfg) -> Planner:
    goals = GoalSet.joint_space(["a", "b"], [[1.0, -0.2], [0.9, 0.2]], ToyRobot)
    stomp = {k: cfg.pop(k) for k in list(cfg) if k in {f.name for f in dataclasses.fields(StompConfig)}}
    config = PlannerConfig(**{"compile": False, **cfg}, stomp=StompConfig(**{"noise_std": 0.1, **stomp}))
    return Planner(scene, config, robot=ToyRobot(), cost=ToyCost(), goals=goals, w_smooth=5.0)


def test_first_step_plans_around_the_blob(scene) -> None:
    planner = toy_planner(scene)
    occ = blob_grid(scene)
    res = planner.step([0.0, -0.2], occ)
    assert res.trajectories.shape == (2, 40, 2) and res.step == 0
    assert np.allclose(res.trajectories[:, 0], [0.0, -0.2]) and np.allclose(res.start, [0.0, -0.2])
    assert np.allclose(res.trajectories[:, -1], [[1.0, -0.2], [0.9, 0.2]], atol=1e-6)
    assert np.all(res.trajectories >= ToyRobot.lower.numpy()) and np.all(res.trajectories <= ToyRobot.upper.numpy())
    assert res.valid.all() and res.chosen in (0, 1) and res.dt > 0 and res.planning_ms > 0
    assert np.allclose(res.cost_total, res.cost_smoothness + res.cost_obstacle + res.cost_human)
    # the cost's waypoint times are the plan's: the dt the executor spends on each segment (half at both ends; the
    # plan's dt is above its min_dt floor here)
    assert res.dt > planner.config.min_dt
    times = planner.waypoint_time(torch.as_tensor(res.trajectories[res.chosen]))
    assert torch.allclose(times[1:-1], torch.tensor(res.dt, dtype=times.dtype), rtol=1e-6)
    assert float(times.sum()) == pytest.approx((res.trajectories.shape[1] - 1) * res.dt, rel=1e-6)
    assert res.cost_total[res.chosen] == res.cost_total.min()
    # the straight line to goal a crosses the blob; the optimised one is >= 10x less penetrating
    line = torch.stack([torch.linspace(0, 1, 40), torch.full((40,), -0.2)], -1)[None]
    straight = float(planner.cost_terms(line)["human"][0])
    assert res.cost_human[0] * 10 <= straight


def test_next_step_starts_ahead_on_tau_best(scene, caplog) -> None:
    planner = toy_planner(scene, lookahead_s=0.3, iterations=20)
    occ = blob_grid(scene)
    first = planner.step([0.0, -0.2], occ)
    tau = torch.as_tensor(first.trajectories[first.chosen])
    q_now = tau[3]  # the robot followed tau_best for 3 waypoints
    second = planner.step(q_now.numpy(), occ)
    assert second.step == 1
    assert np.allclose(second.trajectories[:, 0], second.start)
    # q_t lies on tau_best, 0.3 s further than q_now
    s_expected = 3 + 0.3 / first.dt
    i = int(s_expected)
    expected = tau[i] + (s_expected - i) * (tau[i + 1] - tau[i])
    assert np.allclose(second.start, expected.numpy(), atol=1e-4)
    assert np.allclose(second.trajectories[:, -1], [[1.0, -0.2], [0.9, 0.2]], atol=1e-6)
    assert not first.off_path and not second.off_path
    # off the path: restart from the robot's own configuration, said at DEBUG (it was an INFO line per plan) and on
    # the result, which the service's periodic summary counts
    with caplog.at_level(logging.DEBUG, logger="foresight"):
        third = planner.step([0.0, 0.25], occ)
    assert np.allclose(third.start, [0.0, 0.25]) and np.allclose(third.trajectories[:, 0], [0.0, 0.25])
    assert third.off_path
    (rec,) = [r for r in caplog.records if "from tau_best" in r.getMessage()]
    assert rec.levelno == logging.DEBUG


def test_departure_lookahead_override_and_anytime_step(scene) -> None:
    planner = toy_planner(scene, lookahead_s=0.3, iterations=20, anytime_min_iterations=5)
    occ = blob_grid(scene)
    assert planner.departure([0.0, -0.2]) is None  # no plan yet
    first = planner.step([0.0, -0.2], occ, interrupt=lambda: True)
    assert first.iterations == 5  # a newer input was always waiting: stopped after the minimum
    tau = first.trajectories[first.chosen]
    assert planner.departure(tau[3]) == pytest.approx(0.0, abs=1e-5)
    assert planner.departure([0.0, 0.25]) > planner.config.off_path_tol
    for bad in (float("nan"), float("inf"), -0.1):  # NaN: an IndexError stopped the service; inf: began at the goal
        with pytest.raises(PlannerInputError, match=r"lookahead_s must be finite and >= 0, got"):
            planner.step(tau[3], occ, lookahead_s=bad)
    second = planner.step(tau[3], occ, lookahead_s=0.0, interrupt=lambda: False)
    assert second.iterations == 20 and np.allclose(second.start, tau[3], atol=1e-5)  # no lookahead: starts there


def test_a_state_just_past_a_limit_has_not_departed_from_the_plan_made_from_it(scene) -> None:
    """A state within limit_tol past the limits is planned from clamped; measured unclamped, the robot was off the
    plan it had just been given, and the real-time loop replanned from that one state 59 times in 3 s (a review)."""
    planner = toy_planner(scene, iterations=3)
    past = [-0.5 - 0.04, -1.0 - 0.04]  # both joints 0.04 below their lower limits: 0.057 rad from the clamped start
    res = planner.step(past, blob_grid(scene))
    assert np.allclose(res.start, [-0.5, -1.0])
    assert planner.departure(past) == pytest.approx(0.0, abs=1e-6)  # not over off_path_tol (0.05)
    assert planner.departure([-0.5, -0.9]) > planner.config.off_path_tol  # a real departure still counts


def test_a_reached_goal_holds_still_from_where_the_robot_is(scene) -> None:
    """A reached goal's trajectory was the goal throughout: its waypoint 0, where the robot is to be, was up to
    goal_tol away from q_t, and the executor takes waypoint 0 (a review: 0.14 rad with goal_tol 0.2)."""
    planner = toy_planner(scene, goal_tol=0.2, iterations=3)
    res = planner.step([0.9, -0.1], blob_grid(scene))  # 0.14 from goal a
    a = res.trajectories[0]
    assert np.allclose(a[0], [0.9, -0.1]) and np.allclose(a[1:], [1.0, -0.2])  # from q_t, then at the goal, still
    assert np.allclose(res.trajectories[:, 0], res.start)  # every goal's trajectory starts at q_t
    with pytest.raises(ConfigError, match="planner.goal_tol"):  # every goal 'reached': the robot never moved
        PlannerConfig(goal_tol=float("inf")).validate()
    with pytest.raises(ConfigError, match="planner.goals: each cup once, got red_cup,red_cup"):  # a plan of goals
        PlannerConfig(goals=["red_cup", "red_cup"]).validate()  # ["red_cup", "red_cup"], which receivers refuse


def test_bad_input_is_refused_and_the_planner_keeps_working(scene) -> None:
    planner = toy_planner(scene, iterations=5)
    occ = blob_grid(scene)
    with pytest.raises(PlannerInputError, match="shape"):
        planner.step([0.0, 0.0], occ[:-1])
    nan = occ.copy()
    nan[3, 4, 5] = np.nan
    with pytest.raises(PlannerInputError, match="NaN"):
        planner.step([0.0, 0.0], nan)
    with pytest.raises(PlannerInputError, match=r"\[0, 1\]"):
        planner.step([0.0, 0.0], occ * 3)
    with pytest.raises(PlannerInputError, match="outside the joint limits: y"):
        planner.step([0.0, 0.5], occ)
    with pytest.raises(PlannerInputError, match="shape"):
        planner.step([0.0, 0.0, 0.0], occ)
    with pytest.raises(PlannerInputError, match="NaN"):
        planner.step([np.nan, 0.0], occ)
    assert planner.step_index == 0
    res = planner.step([0.0, 0.3 + 5e-4], occ)  # within limit_tol: clamped
    assert np.allclose(res.start, [0.0, 0.3]) and res.step == 0


def test_occupancy_message_equals_dense(scene) -> None:
    occ = blob_grid(scene)
    msg = OccupancyGrid.from_dense(occ, scene.grid.origin, scene.grid.resolution, stamp=0.0, tick=-1, demo_id=0,
                                   index=0, method="prediction", tick_last=True)
    a = toy_planner(scene, iterations=10).step([0.0, -0.2], msg)
    b = toy_planner(scene, iterations=10).step([0.0, -0.2], msg.to_dense())
    assert np.array_equal(a.trajectories, b.trajectories)  # same seeds: deterministic
    bad = OccupancyGrid.from_dense(occ[:, :, :10], scene.grid.origin, scene.grid.resolution, stamp=0.0, tick=-1,
                                   demo_id=0, index=0, method="prediction", tick_last=True)
    bad.indices = np.array([10**8], dtype=np.uint32)
    bad.values = np.array([3], dtype=np.uint8)
    with pytest.raises(PlannerInputError, match="occupancy grid"):
        toy_planner(scene, iterations=2).step([0.0, -0.2], bad)



def test_a_grid_message_one_voxel_thin_is_refused_as_planner_input(scene) -> None:
    """A valid message on the wire, but the planner's trilinear lookup needs two voxels per axis: refused as
    :class:`PlannerInputError` like every other bad grid (it was a bare ValueError from the cost)."""
    thin = OccupancyGrid.from_dense(np.zeros((1, 4, 4), np.float32), scene.grid.origin, scene.grid.resolution,
                                    stamp=0.0, tick=-1, demo_id=0, index=0, method="prediction", tick_last=True)
    planner = toy_planner(scene, iterations=2)
    with pytest.raises(PlannerInputError, match=r"\(1, 4, 4\).*at least 2 voxels"):
        planner.step([0.0, -0.2], thin)
    assert planner.step_index == 0

def test_invalid_goals_are_reported_and_never_chosen(scene) -> None:
    goals = GoalSet.joint_space(["in", "out", "nan"], [[1.0, -0.2], [2.0, 0.0], [np.nan, 0.0]], ToyRobot)
    assert goals.valid.tolist() == [True, False, False] and "outside the joint limits" in goals.reasons[1]
    config = PlannerConfig(compile=False, stomp=StompConfig(iterations=5))
    planner = Planner(scene, config, robot=ToyRobot(), cost=ToyCost(), goals=goals)
    res = planner.step([0.0, -0.2], blob_grid(scene))
    assert res.valid.tolist() == [True, False, False] and res.chosen == 0
    assert np.isinf(res.cost_total[1:]).all() and np.allclose(res.trajectories[1:], [0.0, -0.2])
    assert res.reasons[1]
    none = GoalSet.joint_space(["out"], [[2.0, 0.0]], ToyRobot)
    with pytest.raises(PlannerError, match="no reachable goal"):
        Planner(scene, PlannerConfig(), robot=ToyRobot(), cost=ToyCost(), goals=none)


# ----------------------------------------------------------------------------------------------
# the PR2 with its real state cost (signed distance field, occupancy, self-collision) and IK goals


@pytest.fixture(scope="module")
def pr2_planner():
    return Planner(load_scene(), PlannerConfig(seed=1, compile=False))


def test_pr2_plans_around_a_blob_on_the_straight_path(pr2_planner) -> None:
    planner = pr2_planner
    planner.reset()
    scene = planner.scene
    assert planner.goals.valid.all(), planner.goals.reasons
    q0 = planner.robot.q_start
    line = init_straight_lines(q0, planner.goal_q, 40)  # (K, T, D)
    mid = planner.robot.end_effector(line[0, 20])[:3, 3].numpy()  # blob on goal 0's straight path
    occ = blob_grid(scene, center=tuple(mid), sigma=0.06)
    res = planner.step(q0.numpy(), occ)
    lo, hi = planner.robot.lower.numpy(), planner.robot.upper.numpy()
    assert np.all(res.trajectories >= lo) and np.all(res.trajectories <= hi)
    assert np.allclose(res.trajectories[:, 0], q0.numpy()) and np.allclose(res.trajectories[:, -1], planner.goal_q)
    # the blob's tail at the goals costs every trajectory the same (goal_dwell_s there): the paths' share falls
    at_goal = planner.cost_terms(planner.goal_q[:, None].expand(-1, 40, -1))["human"].numpy()
    assert np.all(at_goal > 0)
    straight = planner.cost_terms(line)["human"].numpy() - at_goal
    path = res.cost_human - at_goal
    assert path[0] * 10 <= straight[0], (path, straight)
    assert np.all(path * 3 <= straight)  # the other goal's line crosses the blob's tail: less, too
    assert np.all(np.isfinite(res.cost_total)) and res.dt > 0
    nxt = planner.step(res.start, occ)  # replanning from where the plan starts keeps the goals
    assert np.allclose(nxt.trajectories[:, -1], planner.goal_q) and nxt.step == 1


def test_pr2_bad_occupancy_and_start(pr2_planner) -> None:
    planner = pr2_planner
    planner.reset()
    q0 = planner.robot.q_start.numpy()
    occ = np.zeros(planner.scene.grid.dims, dtype=np.float32)
    with pytest.raises(PlannerInputError, match="shape"):
        planner.step(q0, occ[..., :5])
    occ[0, 0, 0] = np.nan
    with pytest.raises(PlannerInputError, match="NaN"):
        planner.step(q0, occ)
    bad = q0.copy()
    bad[4] = 0.5  # elbow flex upper limit is 0
    with pytest.raises(PlannerInputError, match="r_elbow_flex_joint"):
        planner.step(bad, np.zeros(planner.scene.grid.dims, dtype=np.float32))
    assert planner.step_index == 0


def test_pr2_unreachable_cup_is_dropped_and_reported() -> None:
    import dataclasses

    scene = load_scene()
    far = dataclasses.replace(scene.cup("red_cup"), position=np.array([-1.8, -2.8, 0.73]))  # far end of the room
    scene = dataclasses.replace(scene, cups=(scene.cup("blue_cup"), far))
    planner = Planner(scene, PlannerConfig(stomp=StompConfig(iterations=5), compile=False))
    assert planner.goals.valid.tolist() == [True, False]
    res = planner.step(planner.robot.q_start.numpy(), np.zeros(scene.grid.dims, dtype=np.float32))
    assert res.valid.tolist() == [True, False] and res.chosen == 0 and res.reasons[1]
    assert np.isinf(res.cost_total[1]) and np.allclose(res.trajectories[1], res.start)


def test_config_resolves_and_names_bad_values() -> None:
    import argparse

    from services.planner.config import PlannerServiceConfig
    from shared.config import ConfigError, add_config_arguments, resolve_config

    parser = argparse.ArgumentParser()
    add_config_arguments(parser, "planner", PlannerServiceConfig)
    args = parser.parse_args(["--stomp.rollouts", "24", "--goals", "red_cup,blue_cup", "--mode", "lockstep"])
    cfg, _ = resolve_config("planner", PlannerServiceConfig, args, env={"FORESIGHT_PLANNER_COST_W_SMOOTH": "50"})
    p = cfg.planner
    assert (p.stomp.rollouts, p.goals, p.cost.w_smooth, cfg.mode) == (24, ["red_cup", "blue_cup"], 50.0, "lockstep")
    assert p.stomp_config().rollouts == 24 and cfg.planner_config().lookahead_s == 0.0 and p.lookahead_s == 0.5
    with pytest.raises(ConfigError, match=r"planner\.lookahead_s: bad value inf"):
        PlannerConfig(lookahead_s=float("inf")).validate()
    with pytest.raises(ConfigError, match=r"planner\.stomp\.rollouts must be in \[2, 1024\], got 1"):
        PlannerConfig(stomp=StompConfig(rollouts=1)).validate()
    with pytest.raises(ConfigError, match=r"planner\.stomp\.rollouts must be in \[2, 1024\]"):  # 10^12: torch
        PlannerConfig(stomp=StompConfig(rollouts=10**12)).validate()  # asked for 2.5 PB, in a traceback
    with pytest.raises(ConfigError, match=r"planner\.stomp\.waypoints: at most 4096"):
        PlannerConfig(stomp=StompConfig(waypoints=10**6)).validate()
    with pytest.raises(ConfigError, match=r"planner\.stomp\.iterations must be >= 1"):  # 0 failed in the first plan
        PlannerConfig(stomp=StompConfig(iterations=0)).validate()
    with pytest.raises(ConfigError, match=r"planner\.cost\.w_human"):
        PlannerConfig(cost=CostConfig(w_human=-1)).validate()
    with pytest.raises(ConfigError, match="planner.velocity_scale"):
        PlannerConfig(velocity_scale=0).validate()
    with pytest.raises(ConfigError, match="planner.seed: bad value -1"):  # every step failed in SeedSequence
        PlannerConfig(seed=-1).validate()
    with pytest.raises(ConfigError, match=r"^--stomp\.iterations: expected int"):
        resolve_config("planner", PlannerServiceConfig, parser.parse_args(["--stomp.iterations", "x"]), env={})
    for period in (float("inf"), float("nan"), 0.0):  # inf: the real-time loop's wait overflowed and it died
        with pytest.raises(ConfigError, match=r"^planner\.period_s: must be a finite number > 0"):
            PlannerServiceConfig(period_s=period).validate()


def test_bench_json_prints_one_object(capsys) -> None:
    import json

    from services.planner.bench import main

    assert main(["--json", "--k", "1,2", "--steps", "1", "--iterations", "2", "--no-compile"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["K"] == [1, 2]
    for key in ("step_ms", "fk_ms", "ratio", "pk_fk_ms", "cost_ms"):
        assert len(report[key]) == 2 and all(v > 0 for v in report[key])
    with pytest.raises(SystemExit):
        main(["--k", "0"])


def test_algorithm1_loop_reaches_a_goal_following_tau_best(scene) -> None:
    planner = toy_planner(scene, iterations=20, lookahead_s=0.5)
    occ = blob_grid(scene)
    goals = np.array([[1.0, -0.2], [0.9, 0.2]])
    q = np.array([0.0, -0.2])
    chosen = []
    for _ in range(30):
        res = planner.step(q, occ)
        assert np.allclose(res.trajectories[:, 0], res.start, atol=1e-6)
        assert np.all(res.trajectories >= ToyRobot.lower.numpy()) and np.all(res.trajectories <= ToyRobot.upper.numpy())
        chosen.append(res.chosen)
        tau = torch.as_tensor(res.trajectories[res.chosen])
        from services.planner.multigoal import interpolate_path

        q = interpolate_path(tau, 0.5 / res.dt).numpy()  # the robot executes the plan for lookahead_s
        if np.linalg.norm(q - goals[res.chosen]) < 1e-4:
            break
    assert np.linalg.norm(q - goals[chosen[-1]]) < 1e-4, (q, chosen)
    assert len(chosen) > 2


def test_pr2_algorithm1_loop_reaches_the_chosen_goal(pr2_planner) -> None:
    """Replanning while following tau_best converges: the remaining path is not re-inflated each step."""
    from services.planner.multigoal import interpolate_path

    planner = pr2_planner
    planner.reset()
    occ = blob_grid(planner.scene, center=(0.19, -0.77, 0.93), sigma=0.12)  # between the cups
    q = planner.robot.q_start.numpy()
    for _ in range(8):
        res = planner.step(q, occ)
        tau = torch.as_tensor(res.trajectories[res.chosen])
        q = interpolate_path(tau, planner.config.lookahead_s / res.dt).numpy()  # executed while planning
        if np.allclose(res.start, res.trajectories[res.chosen, -1], atol=1e-5):
            break
    assert np.allclose(res.start, res.trajectories[res.chosen, -1], atol=1e-5), "goal not reached in 8 steps"
    assert np.allclose(res.trajectories[res.chosen], res.start)  # a reached goal holds still


def test_pr2_held_goal_pays_its_dwell_in_the_occupancy(pr2_planner) -> None:
    """A robot holding a goal inside the human's volume pays goal_dwell_s x the occupancy there, and leaves."""
    planner = pr2_planner
    scene = planner.scene
    goal = planner.goal_q[0]
    hand = planner.robot.end_effector(goal)[:3, 3].numpy()
    occ = blob_grid(scene, center=tuple(hand), sigma=0.08)  # the human is predicted at goal 0
    planner.cost.set_occupancy(occ, scene.grid.origin, scene.grid.resolution)
    held = goal.expand(1, 40, -1)
    at_goal = float(planner.cost(goal[None, None])[0, 0, 1])  # w_human x summed occupancy at the goal
    assert at_goal > 0.1
    for fused in (planner.fused, None):
        keep, planner.fused = planner.fused, fused
        try:
            human = float(planner.cost_terms(held)["human"][0])
        finally:
            planner.fused = keep
        assert human == pytest.approx(planner.config.goal_dwell_s * at_goal, rel=1e-5)
    chosen = {}
    for dwell in (0.0, 1.0):
        config = dataclasses.replace(planner.config, goal_dwell_s=dwell)
        one = Planner(scene, config, robot=planner.robot, cost=planner.cost, goals=planner.goals)
        res = one.step(goal.numpy(), occ)
        assert np.allclose(res.trajectories[0], goal.numpy())  # goal 0 is reached: its trajectory holds it
        assert res.cost_human[0] == pytest.approx(dwell * at_goal, rel=1e-5, abs=1e-9)
        chosen[dwell] = res.chosen
    assert chosen == {0.0: 0, 1.0: 1}  # held for free it stays in the human's way; charged, it leaves


@pytest.mark.parametrize(("device", "match"), [("tpu", "not a torch device|only cpu and cuda"),
                                                ("cuda:7", "CUDA")])
def test_device_the_machine_lacks_is_named(device: str, match: str) -> None:
    if device.startswith("cuda") and torch.cuda.device_count() > 7:
        pytest.skip("this machine has 8 GPUs")
    with pytest.raises(ConfigError, match=match):
        PlannerConfig(device=device).validate()


def test_goals_per_call_divides_k() -> None:
    from services.planner.core import goals_per_call

    ks = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 16)
    assert [goals_per_call(k, 4) for k in ks] == [1, 2, 3, 4, 5, 3, 7, 4, 3, 2, 4]  # divisors, else one call
    assert goals_per_call(16, 0) == 16 and goals_per_call(0, 4) == 1


@pytest.mark.parametrize("value", [-0.5, float("inf"), float("nan")])
def test_goal_dwell_must_be_finite_and_non_negative(value: float) -> None:
    with pytest.raises(ConfigError, match="goal_dwell_s"):
        PlannerConfig(goal_dwell_s=value).validate()


_HOST_READS = ("item", "tolist", "numpy", "cpu", "__bool__", "__float__", "__int__", "__index__", "nonzero")
"""Tensor methods that read a value back to the host (a device synchronisation on CUDA)."""


def _host_reads(monkeypatch: pytest.MonkeyPatch, fn) -> int:  # noqa: ANN001
    """How many times ``fn()`` reads a tensor back to the host (torch.Tensor methods and torch.nonzero)."""
    calls = [0]

    def counted(orig):  # noqa: ANN001, ANN202
        def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            calls[0] += 1
            return orig(*args, **kwargs)
        return wrapper

    with monkeypatch.context() as m:
        for name in _HOST_READS:
            m.setattr(torch.Tensor, name, counted(getattr(torch.Tensor, name)))
        m.setattr(torch, "nonzero", counted(torch.nonzero))
        fn()
    return calls[0]


def test_pr2_stomp_iterations_never_read_back_to_the_host(pr2_planner, monkeypatch) -> None:
    """The iteration loop (rollouts, the PR2's fused cost, update) reads nothing back to the host, so that on
    CUDA it never waits for the device: the reads of a STOMP call do not grow with its iterations."""
    planner = pr2_planner
    planner.reset()
    occ = blob_grid(planner.scene)
    grid = planner.scene.grid
    planner.cost.set_occupancy(torch.as_tensor(occ), grid.origin, grid.resolution)
    init = init_straight_lines(planner.robot.q_start, planner.goal_q, planner.config.stomp.waypoints)
    seeds = list(range(len(planner.goal_q)))
    reads, config = {}, planner.stomp.config
    try:
        for n in (2, 7):
            planner.stomp.config = dataclasses.replace(config, iterations=n)
            reads[n] = _host_reads(monkeypatch, lambda: planner.stomp.optimize(init, planner.waypoint_cost, seeds))
    finally:
        planner.stomp.config = config
    assert reads[2] > 0  # the checks before the loop read (so the counting works) ...
    assert reads[7] == reads[2], reads  # ... the iterations do not


@pytest.mark.parametrize("choice, expected", [("total", 0), ("human", 1)])
def test_goal_choice_picks_the_lower_term_it_names(scene, choice: str, expected: int) -> None:
    planner = toy_planner(scene, goal_choice=choice, iterations=2)
    real = planner.cost_terms

    def terms(q: torch.Tensor) -> dict[str, torch.Tensor]:  # goal a: lower total, goal b: lower prediction cost
        out = real(q)
        out["human"] = torch.tensor([0.5, 0.1])
        out["total"] = torch.tensor([1.0, 2.0])
        return out

    planner.cost_terms = terms  # type: ignore[method-assign]
    res = planner.step([0.0, -0.2], blob_grid(scene))
    assert res.chosen == expected
    assert res.trajectories[res.chosen, -1].tolist() == pytest.approx([[1.0, -0.2], [0.9, 0.2]][expected])


def test_a_goal_whose_cost_is_not_finite_is_invalid_for_the_step_and_none_leaves_the_state(pr2_planner,
                                                                                            monkeypatch) -> None:
    """A NaN cost on a valid goal made the Plan unpublishable after the planner had adopted it (the next steps
    reconnected from a plan the executor never got), and with goal_choice human it was goal 0 that was chosen."""
    planner = pr2_planner
    planner.reset()
    q0 = planner.robot.q_start.numpy()
    occ = np.zeros(planner.scene.grid.dims, np.float32)
    first = planner.step(q0, occ)
    terms = planner.cost_terms

    def nan_on(goals):
        def patched(q):
            out = {k: v.clone() for k, v in terms(q).items()}
            for g in goals:
                if g < out["human"].shape[0]:
                    out["human"][g] = float("nan")
            out["total"] = out["smoothness"] + out["obstacle"] + out["human"]
            return out
        return patched

    monkeypatch.setattr(planner, "cost_terms", nan_on([1]))
    res = planner.step(first.start, occ)
    assert res.valid.tolist() == [True, False] and res.reasons[1] == "its cost is not finite this step"
    assert res.chosen == 0 and np.isinf(res.cost_total[1]) and np.all(np.isfinite(res.cost_total[:1]))
    from shared.protocol import Plan  # what the service publishes is within the wire contract
    Plan(stamp=1.0, tick=-1, step=res.step, goal_names=res.goal_names, joint_names=res.joint_names, dt=res.dt,
         chosen=res.chosen, planning_ms=res.planning_ms, occupancy_tick=-1, occupancy_index=-1,
         trajectories=res.trajectories.astype(np.float32), cost_smoothness=res.cost_smoothness,
         cost_obstacle=res.cost_obstacle, cost_human=res.cost_human, cost_total=res.cost_total,
         valid=res.valid).check()
    step = planner.step_index
    monkeypatch.setattr(planner, "cost_terms", nan_on([0, 1]))
    with pytest.raises(PlannerError, match="no goal has a finite cost this step"):
        planner.step(res.start, occ)
    assert planner.step_index == step  # the last plan stands


def test_a_scene_without_cups_says_so_and_a_dropped_goal_is_warned_once(scene, caplog) -> None:
    """The planner said ``no reachable goal: `` and nothing after it; each dropped goal was warned twice."""
    empty = dataclasses.replace(scene, cups=())
    with pytest.raises(PlannerError, match=rf"no reachable goal: the scene has no cups \({scene.name}\) to plan for"):
        Planner(empty, PlannerConfig(compile=False))
    far = dataclasses.replace(scene.cups[0], position=np.asarray(scene.cups[0].position) + np.array([0.0, 0.0, 5.0]))
    with caplog.at_level(logging.WARNING):
        Planner(dataclasses.replace(scene, cups=(far, *scene.cups[1:])), PlannerConfig(compile=False))
    dropped = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
    assert len(dropped) == 1 and dropped[0].startswith(f"goal {far.name} dropped: "), dropped
