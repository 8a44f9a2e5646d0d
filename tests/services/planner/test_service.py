"""The planner service's real-time loop on a loopback session: a step that fails is not restarted at once, a held
robot's plans start where it is, the person's newest pose is the body the plans keep clear of."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from services.planner.core import Planner, PlannerConfig
from services.planner.service import PlannerService, PlannerServiceConfig
from services.planner.stomp import StompConfig
from shared.config import ZenohConfig
from shared.human import HumanModel, StreamPlacement
from shared.protocol import HumanPose, Keys, OccupancyGrid, Plan, RobotState
from shared.protocol.limits import JOINT_LIMIT_TOL
from shared.synthetic import generate_library
from shared.transport import TypedPublisher, open_session, subscribe


@contextlib.contextmanager
def _serving(scene, zenoh_hub: Callable[[], ZenohConfig], period_s: float = 0.5,
             **planner_options: object) -> Iterator[tuple[PlannerService, object, Keys, threading.Thread]]:
    """A real-time planner service (3 STOMP iterations, eager), a session of the same hub and the service's thread.

    Yields ``(service, session, keys, thread)``: the caller starts the thread (after subscribing what it must see);
    the service is stopped and the thread joined (10 s at most) on the way out.
    """
    planner = Planner(scene, PlannerConfig(compile=False, stomp=StompConfig(iterations=3), **planner_options))
    hub = zenoh_hub()
    service = PlannerService(PlannerServiceConfig(mode="realtime", trigger="event", period_s=period_s), zenoh_hub(),
                             planner=planner, scene=scene)
    stop = threading.Event()
    thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
    with open_session(hub) as session:
        try:
            yield service, session, Keys(hub.prefix), thread
        finally:
            stop.set()
            if thread.ident is not None:  # started
                thread.join(10.0)
    assert not thread.is_alive()


def _state(q: np.ndarray, names: list[str], holding: bool = False, reason: str = "") -> RobotState:
    return RobotState(stamp=time.time(), tick=-1, joint_names=names, goal=-1, reached=False, holding=holding,
                      reason=reason, q=q, qd=np.zeros(len(q)))


def test_the_default_limit_tolerance_is_the_wire_s() -> None:
    assert PlannerConfig().limit_tol == JOINT_LIMIT_TOL  # a state the receipt accepts is one the planner plans from


def test_a_departure_step_that_fails_waits_for_the_next_state(scene, zenoh_hub: Callable[[], ZenohConfig],
                                                              wait_until: Callable[..., bool]) -> None:
    """Off its path and refused by the planner (here: past a tighter limit tolerance than the wire's), the robot
    used to restart a failing 'departure' step as fast as it failed (about 750 a second, each logged)."""
    with _serving(scene, zenoh_hub, limit_tol=1e-3) as (service, session, keys, thread):
        robot = service.planner.robot
        names, q0 = list(robot.joint_names), robot.q_start.double().numpy()
        thread.start()
        pub = TypedPublisher(session, keys.robot_state)
        assert wait_until(lambda: (pub.put(_state(q0, names)), service.stats.plans)[1] >= 1, 60.0)
        bad = q0.copy()
        bad[1] = robot.upper[1].item() + 0.02  # within the wire's 0.05, beyond the planner's 1e-3
        failures = service.stats.failures
        pub.put(_state(bad, names))
        assert wait_until(lambda: service.stats.failures > failures, 10.0)
        time.sleep(1.5)
        # once for the state, then at most once per period (0.5 s): not once per pass of the loop
        assert 1 <= service.stats.failures - failures <= 1 + 4, service.stats.failures - failures
        assert "outside the joint limits" in service.stats.last_error


def test_a_held_robot_gets_plans_that_start_where_it_is(scene, zenoh_hub: Callable[[], ZenohConfig],
                                                        wait_until: Callable[..., bool],
                                                        caplog: pytest.LogCaptureFixture) -> None:
    """Held still, the robot got plans starting one lookahead ahead of it; the next step counted it as departed
    from that start and replanned from where it was, and so on: about half the plans (34 of 75) started away from
    it, and a third of the steps (20 'departure' steps) were spent correcting that."""
    caplog.set_level(logging.DEBUG, logger="foresight.planner")
    plans: list[Plan] = []
    with _serving(scene, zenoh_hub) as (service, session, keys, thread):
        robot = service.planner.robot
        names, q0 = list(robot.joint_names), robot.q_start.double().numpy()
        sub = subscribe(session, keys.plan, Plan, plans.append)
        thread.start()
        try:
            states, grids = TypedPublisher(session, keys.robot_state), TypedPublisher(session, keys.occupancy)
            held = _state(q0, names, holding=True, reason="plan is 0.60 s old")
            assert wait_until(lambda: (states.put(held), service.stats.plans)[1] >= 1, 60.0)
            g = scene.grid
            for i in range(8):  # each new prediction is a step
                states.put(held)
                grids.put(OccupancyGrid.from_dense(np.zeros(g.dims, np.float32), g.origin, g.resolution,
                                                   stamp=time.time(), tick=-1, tick_last=True, demo_id=0, index=i,
                                                   method="prediction"))
                time.sleep(0.3)
            assert wait_until(lambda: len(plans) >= 6, 30.0)
        finally:
            sub.undeclare()
    starts = [float(np.linalg.norm(p.trajectories[p.chosen, 0] - q0)) for p in plans]
    assert max(starts) < 1e-3, starts
    # each plan's debug line says how many STOMP iterations ran (a slow step: many, or a stalled few?)
    lines = [r.getMessage() for r in caplog.records if r.name == "foresight.planner" and r.levelno == logging.DEBUG]
    assert lines and all(m.endswith(", 3 STOMP iterations") for m in lines), lines


def test_a_real_time_planner_keeps_clear_of_the_person_s_newest_pose(scene, zenoh_hub: Callable[[], ZenohConfig],
                                                                     wait_until: Callable[..., bool]) -> None:
    """The cost's body (``services.planner.body``) is the newest pose's, placed from its demonstration's first."""
    features = generate_library(seed=0).demos[0].features.astype(np.float64)
    placement = StreamPlacement(scene)
    placement.place(4, 0, features[0])
    want, _ = HumanModel().capsules(placement.place(4, 20, features[20]))
    with _serving(scene, zenoh_hub, period_s=0.2) as (service, session, keys, thread):
        robot, cost = service.planner.robot, service.planner.cost
        names, q0 = list(robot.joint_names), robot.q_start.double().numpy()
        thread.start()
        states, poses = TypedPublisher(session, keys.robot_state), TypedPublisher(session, keys.pose)
        assert wait_until(lambda: (states.put(_state(q0, names)), service.stats.plans)[1] >= 1, 60.0)
        assert cost.body is None  # no pose yet
        for i in (0, 20):
            poses.put(HumanPose(stamp=time.time(), tick=-1, tick_last=True, demo_id=4, index=i, features=features[i]))

        def placed() -> bool:
            states.put(_state(q0, names))
            return cost.body is not None and np.allclose(cost.body.ends.double().numpy(), want, atol=1e-5)

        assert wait_until(placed, 20.0)


def test_a_robot_off_its_plan_is_planned_for_from_where_its_velocity_takes_it(scene,
                                                                             zenoh_hub: Callable[[], ZenohConfig]
                                                                             ) -> None:
    """Off the path the step planned from the robot's state as stamped: the plan landed a planning time later behind
    the robot, which was driven back to it, and the next step was off that plan again (a review: 32 of 66 plans
    from off the path, alternating)."""
    planner = Planner(scene, PlannerConfig(compile=False, stomp=StompConfig(iterations=3)))
    service = PlannerService(PlannerServiceConfig(mode="realtime"), zenoh_hub(), planner=planner, scene=scene)
    names, q0 = list(planner.robot.joint_names), planner.robot.q_start.double().numpy()
    grid = np.zeros(scene.grid.dims, np.float32)
    first = planner.step(q0, grid, lookahead_s=0.0)
    tau = first.trajectories[first.chosen].astype(np.float64)
    qd = np.full(len(q0), 0.2)
    on = RobotState(stamp=time.time(), tick=-1, joint_names=names, goal=0, reached=False, holding=False,
                    reason="", q=tau[3], qd=qd)
    q, ahead = service._start_of(on, 0.04)
    assert np.array_equal(q, tau[3]) and ahead == 0.04  # on its plan: the planner looks ahead along it
    off = dataclasses.replace(on, q=tau[3] + np.array([0.0, 0.0, 0.3, 0, 0, 0, 0, 0]))
    q, ahead = service._start_of(off, 0.04)
    np.testing.assert_allclose(q, off.q + 0.2 * 0.04)  # where it will be when the plan lands
    assert ahead == 0.0  # and no second lookahead from there
    q, ahead = service._start_of(dataclasses.replace(off, holding=True), 0.0)
    assert np.array_equal(q, off.q) and ahead == 0.0  # held: it stays where it is
    upper = planner.upper.double().numpy()
    at_limit = dataclasses.replace(off, q=np.minimum(off.q, upper), qd=np.full(len(q0), 50.0))
    assert np.all(service._start_of(at_limit, 0.04)[0] <= upper)  # within the joint limits


def test_a_failing_step_is_logged_a_line_a_second_with_the_count(scene, zenoh_hub: Callable[[], ZenohConfig],
                                                                 caplog: pytest.LogCaptureFixture,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure that persists (a robot state the planner refuses, every path into the table) repeated its error line
    at the state rate in real time, 50 a second."""
    from services.planner import service as planner_service

    planner = Planner(scene, PlannerConfig(compile=False, stomp=StompConfig(iterations=3)))
    service = PlannerService(PlannerServiceConfig(mode="realtime"), zenoh_hub(), planner=planner, scene=scene)
    now = [100.0]
    monkeypatch.setattr(planner_service.time, "monotonic", lambda: now[0])
    bad = np.full(len(planner.robot.joint_names), np.nan)
    with caplog.at_level(logging.ERROR, logger="foresight.planner"):
        for i in range(50):
            now[0] = 100.0 + i * 0.02  # one second of states at 50 Hz
            assert service._plan(bad, None, -1, 0.0, pub=None) is None
        now[0] = 101.5
        service._plan(bad, None, -1, 0.0, pub=None)
    lines = [r.getMessage() for r in caplog.records if "failed" in r.getMessage()]
    assert len(lines) == 2 and service.stats.failures == 51, lines
    assert lines[1].endswith("(49 more failed steps since the last such line)"), lines[1]
