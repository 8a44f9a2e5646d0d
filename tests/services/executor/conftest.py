"""Fakes of the other services for the executor tests: a planner that plans straight lines from the
latest robot state to two fixed goals on every clock tick (or at a fixed rate), and a predictor that
publishes one small occupancy grid per tick (or at a fixed rate)."""

from __future__ import annotations

import dataclasses
import functools
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from shared.config import ZenohConfig
from shared.protocol import ClockTick, Keys, Message, OccupancyGrid, Plan, RobotState
from shared.scene import load_scene
from shared.transport import Presence, RejectCounter, TypedPublisher, open_session, subscribe_ordered

SCENE = load_scene(None)


def new_hub():
    """A fresh factory like the ``zenoh_hub`` fixture (the first config listens on a new port)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    made: list[ZenohConfig] = []

    def make() -> ZenohConfig:
        first = not made
        made.append(ZenohConfig(mode="peer", listen=[endpoint] if first else ["tcp/127.0.0.1:0"],
                                connect=[] if first else [endpoint], multicast_scouting=False))
        return made[-1]

    return make


@functools.cache
def _limits() -> tuple[np.ndarray, np.ndarray]:
    import torch

    from shared.robot import PR2

    robot = PR2(dtype=torch.float64)
    return robot.lower.numpy(), robot.upper.numpy()


def goals_for(q0: np.ndarray) -> list[np.ndarray]:
    """Two joint-space goals 0.3-0.5 rad from ``q0``, inside the limits (torso unchanged: it moves 13 mm/s)."""
    lo, hi = _limits()
    out = []
    for delta in ([0.5, 0.3, -0.4, -0.5], [-0.4, 0.3, 0.4, 0.5]):
        g = q0.copy()
        for i, d in enumerate(delta, start=1):  # step towards the side with room
            g[i] = q0[i] + d if lo[i] + 0.05 <= q0[i] + d <= hi[i] - 0.05 else q0[i] - d
        out.append(np.clip(g, lo + 0.05, hi - 0.05))
    return out


def straight_plan(q: np.ndarray, goals: list[np.ndarray], names: list[str], tick: int, step: int, chosen: int,
                  occupancy_tick: int = -1, t: int = 15, dt: float = 0.1) -> Plan:
    traj = np.stack([np.linspace(q, g, t) for g in goals]).astype(np.float32)
    k = len(goals)
    cost = np.arange(1.0, k + 1.0)
    return Plan(stamp=float(tick) * 0.2 if tick >= 0 else time.time(), tick=tick, step=step,
                goal_names=["blue_cup", "red_cup"][:k], joint_names=list(names), dt=dt, chosen=chosen,
                planning_ms=1.0, occupancy_tick=occupancy_tick, occupancy_index=max(occupancy_tick, 0),
                trajectories=traj, cost_smoothness=cost, cost_obstacle=cost * 0, cost_human=cost,
                cost_total=2 * cost, valid=np.ones(k, bool))


def blob(tick: int, index: int, stamp: float) -> OccupancyGrid:
    grid = np.zeros(SCENE.grid.dims, np.float32)
    grid[18 + tick % 3: 24 + tick % 3, 12:20, 15:22] = 0.8
    return OccupancyGrid.from_dense(grid, SCENE.grid.origin, SCENE.grid.resolution, stamp=stamp, tick=tick,
                                    tick_last=True, demo_id=0, index=index, method="prediction")


class FakeSystem:
    """Fake predictor + planner in one Zenoh session.

    Lock-step: on ClockTick n publish occupancy n and the plan of tick n (from the latest RobotState),
    unless n is in ``skip_plans``. Real time: ``start_realtime`` publishes both at ``rate_hz``.
    """

    def __init__(self, zcfg: ZenohConfig, switch_at: int = 10**9, skip_plans: frozenset[int] = frozenset(),
                 waypoints: int = 5) -> None:
        self.waypoints = waypoints
        self.zcfg = zcfg
        self.keys = Keys(zcfg.prefix)
        self.switch_at = switch_at
        self.skip_plans = skip_plans
        self.ticks: list[int] = []
        self.plans: list[Plan] = []
        self.predictor_on = threading.Event()
        self.predictor_on.set()
        self.first_plan = threading.Event()  # cleared: the plan of tick 0 waits for it (the tests' puts go first)
        self.first_plan.set()
        self._stop = threading.Event()
        self._goals: list[np.ndarray] | None = None

    def _plan(self, state: RobotState, tick: int, step: int) -> Plan:
        if self._goals is None:
            self._goals = goals_for(state.q)
        chosen = 0 if step < self.switch_at else 1
        return straight_plan(state.q, self._goals, state.joint_names, tick, step, chosen,
                             occupancy_tick=max(tick - 1, -1),
                             t=self.waypoints)

    @contextmanager
    def running(self, realtime_hz: float | None = None) -> Iterator[FakeSystem]:
        # Publishing from a subscriber callback on keys that a subscriber of the same session matches
        # can deadlock zenoh-python 1.10 when another thread publishes at the same time, so the fake
        # listens in one session and publishes in another (``self.session``: for the tests' own puts).
        out_cfg = dataclasses.replace(self.zcfg, listen=["tcp/127.0.0.1:0"])
        with open_session(self.zcfg) as session, open_session(out_cfg) as out:
            occ_pub = TypedPublisher(out, self.keys.occupancy, block=True)
            plan_pub = TypedPublisher(out, self.keys.plan, block=True)
            self.session, self.occ_pub, self.plan_pub = out, occ_pub, plan_pub
            # one ordered subscription: the last RobotState of step n arrives before ClockTick n
            latest: dict[str, RobotState] = {}

            def on_tick(tick: ClockTick) -> None:
                self.ticks.append(tick.tick)
                if self.predictor_on.is_set():
                    occ_pub.put(blob(tick.tick, tick.tick, tick.stamp))
                state = latest.get("state")
                if state is not None and tick.tick not in self.skip_plans:
                    if tick.tick == 0:
                        self.first_plan.wait(20.0)
                    plan = self._plan(state, tick.tick, tick.tick)
                    self.plans.append(plan)
                    plan_pub.put(plan)

            def on_message(msg: Message) -> None:
                if isinstance(msg, RobotState):
                    latest["state"] = msg
                elif isinstance(msg, ClockTick):
                    on_tick(msg)

            types = {self.keys.robot_state: RobotState, self.keys.clock: ClockTick}
            sub = subscribe_ordered(session, f"{self.keys.prefix}/**", types, on_message,
                                    RejectCounter("fake"))
            # the executor starts when it sees both tokens, i.e. when both sessions are connected to it
            presence = [Presence(session, self.keys, "predictor"), Presence(out, self.keys, "planner")]
            thread = None
            if realtime_hz:
                def loop() -> None:
                    step = 0
                    while not self._stop.wait(1.0 / realtime_hz):
                        if self.predictor_on.is_set():
                            occ_pub.put(blob(-1, step, time.time()))
                        state = latest.get("state")
                        if state is not None:
                            plan = self._plan(state, -1, step)
                            self.plans.append(plan)
                            plan_pub.put(plan)
                        step += 1

                thread = threading.Thread(target=loop, daemon=True)
                thread.start()
            try:
                yield self
            finally:
                self._stop.set()
                if thread is not None:
                    thread.join(timeout=5)
                for p in presence:
                    p.close()
                sub.undeclare()


@pytest.fixture(scope="session")
def pr2():
    import torch

    from shared.robot import PR2

    return PR2.from_scene(SCENE, device="cpu", dtype=torch.float32)

