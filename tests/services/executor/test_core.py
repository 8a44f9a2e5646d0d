"""ExecutorCore: follows the chosen trajectory within the velocity limits, reaches the goal, holds on
stale data and resumes, never leaves the joint limits."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from services.executor.core import ArmLimits, ExecutorConfig, ExecutorCore, ExecutorError, reason_kind
from services.executor.reference import Reference
from shared.config import ConfigError
from shared.protocol import Plan

NAMES = ("j0", "j1", "j2")
LIMITS = ArmLimits(NAMES, np.array([-1.0, -2.0, 0.0]), np.array([1.0, 2.0, 0.3]), np.array([0.5, 1.0, 0.05]))


def make_plan(start: np.ndarray, goals: list[np.ndarray], chosen: int = 0, t: int = 11, dt: float = 0.1,
              tick: int = 0, names: tuple[str, ...] = NAMES) -> Plan:
    traj = np.stack([np.linspace(start, g, t) for g in goals]).astype(np.float32)
    k = len(goals)
    return Plan(stamp=0.0, tick=tick, step=max(tick, 0), goal_names=[f"g{i}" for i in range(k)],
                joint_names=list(names), dt=dt, chosen=chosen, planning_ms=1.0, occupancy_tick=tick,
                occupancy_index=0, trajectories=traj, cost_smoothness=np.zeros(k), cost_obstacle=np.zeros(k),
                cost_human=np.zeros(k), cost_total=np.zeros(k), valid=np.ones(k, bool))


def run(core: ExecutorCore, seconds: float, h: float = 0.02, fresh: bool = True) -> np.ndarray:
    """Step for ``seconds``; keeps occupancy fresh when ``fresh``; returns the visited configurations."""
    qs = []
    for _ in range(round(seconds / h)):
        if fresh:
            core.note_occupancy()
        core.step(h)
        qs.append(core.q.copy())
    return np.array(qs)


def test_holds_until_the_first_plan() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig())
    run(core, 0.2)
    assert core.holding and core.reason == "waiting for the first plan"
    assert np.all(core.q == 0) and np.all(core.qd == 0)
    assert core.state(tick=-1).holding


def test_follows_a_slow_trajectory_exactly_and_reaches_the_goal() -> None:
    cfg = ExecutorConfig(stale_limit_s=10.0)
    core = ExecutorCore(LIMITS, np.zeros(3), cfg)
    goal = np.array([0.3, -0.5, 0.02])
    plan = make_plan(np.zeros(3), [goal, -goal], chosen=0, t=21, dt=0.1)  # 2 s, well within the limits
    core.adopt(plan)
    core.note_occupancy()
    qs = run(core, 1.0)
    ref = Reference(plan.trajectories[0].astype(np.float64), plan.dt)
    assert np.allclose(qs[-1], ref.at(1.0), atol=1e-6)  # on the reference, no lag
    assert not core.reached and core.goal == 0
    run(core, 1.2)
    assert core.reached
    assert np.allclose(core.q, goal, atol=1e-6)
    st = core.state(tick=3)
    assert st.reached and st.goal == 0 and st.tick == 3 and not st.holding


def test_velocity_limits_are_never_exceeded_and_direction_is_kept() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(stale_limit_s=100.0))
    goal = np.array([0.8, 1.5, 0.25])
    core.adopt(make_plan(np.zeros(3), [goal], t=3, dt=0.05))  # demands ~10x the limits
    h = 0.02
    prev = core.q.copy()
    for _ in range(400):
        core.note_occupancy()
        core.step(h)
        v = (core.q - prev) / h
        assert np.all(np.abs(v) <= LIMITS.velocity + 1e-9)
        assert np.all(np.abs(core.qd) <= LIMITS.velocity + 1e-9)
        prev = core.q.copy()
        if core.reached:
            break
    assert core.reached
    # uniform scaling: while the limiting joint moves, the others move proportionally (straight line)
    core2 = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(stale_limit_s=100.0))
    core2.adopt(make_plan(np.zeros(3), [goal], t=2, dt=0.01))
    core2.note_occupancy()
    core2.step(h)
    assert np.allclose(np.cross(core2.q, goal), 0.0, atol=1e-9)


def test_velocity_scale_slows_the_arm() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(velocity_scale=0.5, stale_limit_s=100.0))
    core.adopt(make_plan(np.zeros(3), [np.array([0.0, 0.0, 0.3])], t=2, dt=0.01))
    core.note_occupancy()
    core.step(1.0)
    assert core.q[2] == pytest.approx(0.025)


def test_commanded_configuration_never_leaves_the_joint_limits() -> None:
    rng = np.random.default_rng(0)
    core = ExecutorCore(LIMITS, np.array([5.0, -5.0, 1.0]), ExecutorConfig(stale_limit_s=100.0))
    assert np.all(core.q >= LIMITS.lower) and np.all(core.q <= LIMITS.upper)  # start clamped
    for i in range(30):
        # plans far outside the limits (the planner must not do this; the executor clamps anyway)
        goals = [rng.uniform(-10, 10, size=3) for _ in range(2)]
        core.adopt(make_plan(rng.uniform(-10, 10, size=3), goals, chosen=i % 2, t=5, dt=0.05))
        for _ in range(20):
            core.note_occupancy()
            core.step(0.02)
            assert np.all(core.q >= LIMITS.lower) and np.all(core.q <= LIMITS.upper)
            st = core.state(tick=i)
            assert np.all(st.q >= LIMITS.lower) and np.all(st.q <= LIMITS.upper)


def test_holds_on_stale_plan_and_resumes_where_it_stopped() -> None:
    cfg = ExecutorConfig(stale_limit_s=0.5)
    core = ExecutorCore(LIMITS, np.zeros(3), cfg)
    goal = np.array([0.4, 0.0, 0.0])
    core.adopt(make_plan(np.zeros(3), [goal], t=21, dt=0.1))
    run(core, 0.5)  # plan age reaches 0.5 s: still moving
    assert not core.holding
    q_before = core.q.copy()
    run(core, 0.3)  # plan older than 0.5 s -> hold
    assert core.holding and "plan is" in core.reason and "limit 0.50 s" in core.reason
    assert np.all(core.qd == 0)
    held_at = core.q.copy()
    assert np.all(held_at >= q_before)
    run(core, 1.0)
    assert np.array_equal(core.q, held_at)  # did not move at all while holding
    # fresh plan (same trajectory re-sent from where the robot is) -> resumes
    core.adopt(make_plan(held_at, [goal], t=21, dt=0.1))
    run(core, 0.1)
    assert not core.holding and core.reason == ""
    assert core.q[0] > held_at[0]


def test_holds_on_stale_or_missing_occupancy() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(make_plan(np.zeros(3), [np.array([0.4, 0, 0])], t=21, dt=0.1))
    core.step(0.02)
    assert core.holding and core.reason == "no occupancy prediction received yet"
    core.note_occupancy()
    core.adopt(make_plan(core.q, [np.array([0.4, 0, 0])], t=21, dt=0.1))
    run(core, 0.4, fresh=False)
    assert not core.holding
    core.adopt(make_plan(core.q, [np.array([0.4, 0, 0])], t=21, dt=0.1))  # plan fresh, occupancy not
    run(core, 0.2, fresh=False)
    assert core.holding and core.reason.startswith("occupancy is")
    core.note_occupancy()
    core.adopt(make_plan(core.q, [np.array([0.4, 0, 0])], t=21, dt=0.1))
    core.step(0.02)
    assert not core.holding
    # without require_occupancy only the plan counts
    core2 = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(require_occupancy=False))
    core2.adopt(make_plan(np.zeros(3), [np.array([0.4, 0, 0])], t=21, dt=0.1))
    core2.step(0.02)
    assert not core2.holding


def test_reference_clock_stops_while_holding() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(make_plan(np.zeros(3), [np.array([0.4, 0, 0])], t=21, dt=0.1))
    core.note_occupancy()
    core.step(0.1, hold_reason="")
    tau = core.tau
    core.step(0.1, hold_reason="test hold")
    assert core.tau == tau and core.reason == "test hold"


def test_plan_with_other_joints_is_rejected() -> None:
    core = ExecutorCore(LIMITS, np.zeros(3))
    with pytest.raises(ExecutorError, match="joint_names"):
        core.adopt(make_plan(np.zeros(3), [np.ones(3)], names=("j0", "j2", "j1")))
    assert core.plan is None


@pytest.mark.parametrize("t", [0, 1])
def test_plan_without_a_path_is_rejected_not_crashed_on(t: int) -> None:
    """A Plan built in-process (no decode, so no wire check) with fewer than 2 waypoints: an ExecutorError."""
    core = ExecutorCore(LIMITS, np.zeros(3))
    with pytest.raises(ExecutorError, match=rf"Plan\.trajectories: shape \(1, {t}, 3\)"):
        core.adopt(make_plan(np.zeros(3), [np.ones(3)], t=t))
    assert core.plan is None


def test_bad_inputs_are_named() -> None:
    with pytest.raises(ExecutorError, match="start configuration"):
        ExecutorCore(LIMITS, np.zeros(2))
    with pytest.raises(ExecutorError, match="velocity"):
        ArmLimits(NAMES, np.zeros(3), np.ones(3), np.array([1.0, 0.0, 1.0]))
    with pytest.raises(ExecutorError, match="step"):
        ExecutorCore(LIMITS, np.zeros(3)).step(float("nan"))
    with pytest.raises(ConfigError, match="stale_limit_s"):
        ExecutorConfig(stale_limit_s=0).validate()
    with pytest.raises(ConfigError, match="wait_for"):
        ExecutorConfig(wait_for=["planer"]).validate()
    with pytest.raises(ConfigError, match="live_port: must be a port"):
        ExecutorConfig(live_port=70000).validate()
    with pytest.raises(ConfigError, match="live_port: the live scene is the log's"):
        ExecutorConfig(live_port=8765, mcap="none").validate()


def test_reference_interpolates_and_holds_at_the_ends() -> None:
    ref = Reference(np.array([[0.0, 0.0], [1.0, 2.0], [1.0, 4.0]]), dt=0.5)
    assert np.allclose(ref.at(-1.0), [0, 0])
    assert np.allclose(ref.at(0.25), [0.5, 1.0])
    assert np.allclose(ref.at(0.75), [1.0, 3.0])
    assert np.allclose(ref.at(5.0), [1.0, 4.0])
    assert ref.duration == 1.0


def test_last_prediction_stays_valid_after_the_demonstration_ends():
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5))
    core.fresh.plan, core.fresh.occupancy = 0.0, 0.0
    core.reference = object()  # a plan is being executed
    assert "occupancy" in core.stale_reason(1.0) or "plan" in core.stale_reason(1.0)
    core.fresh.plan = 1.0
    core.note_occupancy_of(4, 99)  # the prediction of demonstration 4's last pose (100 samples)
    assert "occupancy is 1.00 s old" in core.stale_reason(1.0)
    core.note_demonstration("end", demo_id=4, n_samples=100)
    assert core.human_ended and core.stale_reason(1.0) == ""
    core.note_demonstration("start", demo_id=5, n_samples=100)
    assert "occupancy" in core.stale_reason(1.0)


def test_a_reach_lost_mid_way_holds_the_robot_until_a_reach_starts_again():
    """The tracker ended a reach it lost (the person out of view) with an end marker, and the robot went on with
    the lost reach's last prediction as if the person stood still where they were last seen."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.note_occupancy_of(4, 39)  # the prediction of the last pose the tracker saw (40 poses)
    core.note_demonstration("lost", demo_id=4, n_samples=40)
    assert not core.human_ended
    assert core.stale_reason() == ("the tracker lost the person (demonstration 4: out of the sensor's view, another "
                                   "body, or moved away): holding until the person is seen again (at rest or reaching)")
    core.step(0.02)
    assert core.holding and "lost the person" in core.reason
    core.note_demonstration("start", demo_id=5)  # seen again: fresh predictions decide
    core.note_occupancy()
    assert core.stale_reason() == ""
    free = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5, require_occupancy=False))
    free.adopt(_one_joint_plan())
    free.note_demonstration("lost", demo_id=4, n_samples=40)
    assert free.stale_reason() == ""  # no prediction required: none holds it


def test_an_end_marker_does_not_release_a_prediction_of_an_earlier_pose():
    """The predictor died mid-demonstration: its last occupancy is of pose 40, the demonstration ends at
    pose 99. The end marker must not let the robot move on that old prediction (issue 12)."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.note_occupancy_of(4, 40)
    moved = []
    for i in range(100):  # 2 s; the plan stays fresh, the occupancy is never renewed
        core.fresh.plan = core.t
        if i == 40:
            core.note_demonstration("end", demo_id=4, n_samples=100)
        core.step(0.02)
        moved.append((core.t, not core.holding))
    assert any(m for _, m in moved[:10]), "the robot was moving"
    stale_since = 0.5 + 0.02 + 1e-6  # the state after the first step that starts with a stale occupancy
    assert not any(m for t, m in moved if t > stale_since), "released while the occupancy was stale"
    assert "occupancy is" in core.reason and not core.human_ended
    core.note_occupancy_of(4, 99)  # the prediction of the last pose arrives (late)
    core.step(0.02)
    assert not core.holding


def _one_joint_plan() -> Plan:
    traj = np.linspace(0.0, 0.9, 51)[None, :, None].astype(np.float32)
    return Plan(stamp=0.0, tick=-1, step=0, goal_names=["g"], joint_names=["a"], dt=0.1, chosen=0, planning_ms=1.0,
                occupancy_tick=-1, occupancy_index=0, trajectories=traj, cost_smoothness=np.zeros(1),
                cost_obstacle=np.zeros(1), cost_human=np.zeros(1), cost_total=np.zeros(1), valid=np.ones(1, bool))


def test_holds_while_a_service_it_depends_on_is_gone_and_not_after():
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=10.0))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.step(0.02)
    assert not core.holding
    core.note_demonstration("end", 3, 100)
    assert core.note_peer("replayer", False)  # after its end marker: the human's stream may end (said so)
    core.step(0.02)
    assert not core.holding
    assert not core.note_peer("replayer", True)
    core.note_demonstration("start", 4, 100)
    assert not core.note_peer("replayer", False)  # in the middle of a demonstration: the human is unobserved
    assert not core.note_peer("replayer", False)  # told twice: still no stream's end to say
    core.step(0.02)
    assert core.holding and core.reason == "replayer gone (liveliness token lost)"
    core.note_peer("replayer", True)
    core.step(0.02)
    assert not core.holding
    core.note_peer("predictor", False)
    core.step(0.02)
    assert core.holding and core.reason == "predictor gone (liveliness token lost)"
    core.note_peer("planner", False)
    assert core.stale_reason() == "planner and predictor gone (liveliness token lost)"
    core.note_peer("predictor", True)
    core.note_peer("planner", True)
    core.step(0.02)
    assert not core.holding
    quiet = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=10.0, hold_without=[]))
    quiet.adopt(_one_joint_plan())
    quiet.note_occupancy()
    quiet.note_peer("planner", False)
    assert quiet.stale_reason() == ""


def test_a_person_lost_after_a_demonstration_s_end_holds_the_robot_until_one_starts():
    """The tracker's `lost` after an end (the person out of view, or moved away from where it showed them)."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.note_demonstration("end", demo_id=2, n_samples=10)
    core.note_occupancy_of(2, 9)
    assert core.human_ended and core.stale_reason() == ""
    core.note_demonstration("lost", demo_id=2, n_samples=10)
    assert not core.human_ended and "the tracker lost the person (demonstration 2" in core.stale_reason()
    core.note_demonstration("start", demo_id=3)
    core.note_occupancy()
    assert core.stale_reason() == ""


@pytest.mark.parametrize(("recorded", "holds"), [(["replayer"], True), (["replayer", "tracker"], False)])
def test_a_live_tracker_gone_after_an_end_holds_the_robot_a_recording_s_does_not(recorded, holds):
    """Before, any human source going after an end marker let the robot go on for good: a live tracker killed after
    a reach's end left the robot moving around that reach's last prediction, nobody watching the person. A tracker
    that plays a file (`foresight demo --human keypoints`: `recorded_sources`) ends its stream as a replayer does."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=10.0, recorded_sources=recorded))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.note_peer("tracker", True)
    core.note_demonstration("end", 3, 10)
    core.note_occupancy_of(3, 9)
    core.note_peer("tracker", False)
    assert core.stale_reason() == ("tracker gone (liveliness token lost)" if holds else "")
    core.note_peer("tracker", True)  # back (a lost link), or a new one (restarted): it must say the person again
    assert core.stale_reason() == ("the tracker was gone (its last demonstration, 3, may be stale): holding until "
                                   "the person is seen again (at rest or reaching)" if holds else "")
    core.note_demonstration("start", 4)  # the tracker says the person again to the executor it sees appear
    core.note_occupancy()
    assert core.stale_reason() == ""


def test_a_human_source_not_named_among_the_sources_is_a_config_error():
    with pytest.raises(ConfigError, match="executor.recorded_sources: unknown service 'planner'"):
        ExecutorConfig(recorded_sources=["planner"]).validate()


def test_reason_kind_ignores_the_ages():
    assert reason_kind("plan is 0.61 s old (limit 0.50 s)") == reason_kind("plan is 12.00 s old (limit 0.50 s)")
    assert reason_kind("plan is 0.61 s old (limit 0.50 s)") != reason_kind("occupancy is 0.61 s old (limit 0.50 s)")
    assert reason_kind("") == ""


@pytest.mark.parametrize(("device", "match"), [("nonsense", "not a torch device"), ("meta", "only cpu and cuda")])
def test_a_device_the_machine_lacks_is_a_config_error(device: str, match: str) -> None:
    """It ended in a torch traceback when the executor built its robot model."""
    with pytest.raises(ConfigError, match=rf"^executor\.device: '{device}'.*{match}"):
        ExecutorConfig(device=device).validate()
    if not __import__("torch").cuda.is_available():
        with pytest.raises(ConfigError, match="torch sees no CUDA device"):
            ExecutorConfig(device="cuda").validate()


def test_a_lagging_arm_stays_on_the_path_at_a_bend() -> None:
    """The velocity limits slow the arm: the reference waits for it (it used to run on, and the arm cut the
    corner of an L-shaped path by 0.46 rad)."""
    limits = ArmLimits(("a", "b"), np.array([-5.0, -5.0]), np.array([5.0, 5.0]), np.array([1.0, 1.0]))
    core = ExecutorCore(limits, np.zeros(2), ExecutorConfig(stale_limit_s=100.0, require_occupancy=False))
    plan = make_plan(np.zeros(2), [np.zeros(2)], names=("a", "b"))
    plan.trajectories = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]], np.float32)  # 10x the limits
    core.adopt(plan)
    worst = 0.0
    for _ in range(300):
        core.step(0.01)
        x, y = core.q
        worst = max(worst, min(np.hypot(x - np.clip(x, 0, 1), y), np.hypot(x - 1, y - np.clip(y, 0, 1))))
        assert np.all(np.abs(core.qd) <= limits.velocity + 1e-9)
    assert core.reached and worst < 0.02, worst


def test_the_hold_before_a_live_persons_first_reach_says_why() -> None:
    """A live run held for as long as the person stood still (32 s in a review's run), saying only 'no occupancy
    prediction received yet': the tracker publishes poses once it has seen the person (at rest, or reaching)."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=10.0))
    core.adopt(_one_joint_plan())
    core.step(0.02)
    assert core.holding and core.reason == "no occupancy prediction received yet"  # the replayer's case: as before
    core.note_peer("tracker", True)
    core.step(0.02)
    assert core.holding and "the tracker publishes poses once it has seen the person at rest" in core.reason


def test_a_lock_step_stale_limit_below_the_period_is_refused_and_the_demo_passes_one_that_fits() -> None:
    """A plan of tick n-1 is adopted at step n, a period old: with the period above the limit (`foresight demo
    --period-s 0.6`) every step held and the robot never moved (a review)."""
    import dataclasses

    from services.demo import DemoConfig
    from services.demo_services import service_options
    from services.executor.config import lockstep_stale_limit

    with pytest.raises(ConfigError, match=r"executor\.stale_limit_s: 0\.5 s is below the lock-step period 0\.6 s: .* "
                                          r"give at least 0\.9"):
        ExecutorConfig(mode="lockstep", step_period_s=0.6).validate()
    ExecutorConfig(mode="realtime", step_period_s=0.6).validate()  # real time adopts a plan as it arrives
    ExecutorConfig(mode="lockstep", step_period_s=0.5).validate()  # the defaults
    assert lockstep_stale_limit(0.5, 0.5) == 0.5 and lockstep_stale_limit(0.6, 0.5) == pytest.approx(0.9)
    opts = service_options(dataclasses.replace(DemoConfig(), period_s=0.6), Path("m.npz"), Path("l.npz"), 1, None)
    flags = opts["executor"]
    assert flags[flags.index("--stale-limit-s") + 1] == "0.9"
    assert "--stale-limit-s" not in service_options(DemoConfig(), Path("m.npz"), Path("l.npz"), 1, None)["executor"]


def test_a_start_marker_between_the_loops_reads_of_a_lost_person_never_garbles_the_reason():
    """The transport's thread writes the person's loss while the loop reads it: a start marker that came between the
    check and the text read made the reason 'None: holding until the person is seen again' (published, logged)."""
    limits = ArmLimits(("a",), np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    core = ExecutorCore(limits, np.zeros(1), ExecutorConfig(stale_limit_s=0.5))
    core.adopt(_one_joint_plan())
    core.note_occupancy()
    core.note_demonstration("lost", demo_id=4, n_samples=40)

    class StartOnRead(type(core.fresh)):  # the marker's callback runs right after the loop's first read of `lost`
        def __getattribute__(self, name: str) -> object:
            value = super().__getattribute__(name)
            if name == "lost" and value is not None:
                core.note_demonstration("start", demo_id=5)
            return value

    core.fresh = StartOnRead(**dataclasses.asdict(core.fresh))
    reason = core.stale_reason()
    assert reason.startswith("the tracker lost the person (demonstration 4"), reason  # the state it was read in
    assert core.stale_reason() == ""  # the next state: seen again, the prediction fresh
