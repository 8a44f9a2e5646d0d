"""The planner service's real-time loop on a loopback session: a step that fails is not restarted at once."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from services.planner.core import Planner, PlannerConfig
from services.planner.service import PlannerService, PlannerServiceConfig
from services.planner.stomp import StompConfig
from shared.config import ZenohConfig
from shared.protocol import Keys, RobotState
from shared.protocol.limits import JOINT_LIMIT_TOL
from shared.transport import TypedPublisher, open_session


def test_the_default_limit_tolerance_is_the_wire_s() -> None:
    assert PlannerConfig().limit_tol == JOINT_LIMIT_TOL  # a state the receipt accepts is one the planner plans from


def test_a_departure_step_that_fails_waits_for_the_next_state(scene, zenoh_hub: Callable[[], ZenohConfig],
                                                              wait_until: Callable[..., bool]) -> None:
    """Off its path and refused by the planner (here: past a tighter limit tolerance than the wire's), the robot
    used to restart a failing 'departure' step as fast as it failed (about 750 a second, each logged)."""
    config = PlannerConfig(compile=False, stomp=StompConfig(iterations=3), limit_tol=1e-3)
    planner = Planner(scene, config)
    hub = zenoh_hub()
    service = PlannerService(PlannerServiceConfig(mode="realtime", trigger="event", period_s=0.5), zenoh_hub(),
                             planner=planner, scene=scene)
    names = list(planner.robot.joint_names)
    q0 = planner.robot.q_start.double().numpy()
    stop = threading.Event()
    thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
    with open_session(hub) as session:
        thread.start()
        try:
            pub = TypedPublisher(session, Keys(hub.prefix).robot_state)

            def state(q: np.ndarray) -> None:
                pub.put(RobotState(stamp=time.time(), tick=-1, joint_names=names, goal=-1, reached=False,
                                   holding=False, reason="", q=q, qd=np.zeros(len(q))))

            assert wait_until(lambda: (state(q0), service.stats.plans)[1] >= 1, 60.0)
            bad = q0.copy()
            bad[1] = planner.robot.upper[1].item() + 0.02  # within the wire's 0.05, beyond the planner's 1e-3
            failures = service.stats.failures
            state(bad)
            assert wait_until(lambda: service.stats.failures > failures, 10.0)
            time.sleep(1.5)
            # once for the state, then at most once per period (0.5 s): not once per pass of the loop
            assert 1 <= service.stats.failures - failures <= 1 + 4, service.stats.failures - failures
            assert "outside the joint limits" in service.stats.last_error
        finally:
            stop.set()
            thread.join(10.0)
    assert not thread.is_alive()
