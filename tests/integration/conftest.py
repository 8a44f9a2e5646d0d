"""In-process system harness: the four services in one test process, each with its own Zenoh session.

The test process's first session (the hub) listens on a free loopback port; every service connects
to it. Multicast scouting is off everywhere. Every thread is joined with a bounded timeout.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from services.executor.core import ExecutorConfig
from services.executor.service import ExecutorResult, ExecutorService
from services.experiments.harness import JOIN_S, ServiceThread
from services.planner.config import PlannerConfig
from services.planner.service import PlannerService, PlannerServiceConfig
from services.planner.stomp import StompConfig
from services.predictor.core import PredictorConfig
from services.predictor.service import PredictorService
from services.processes import free_port
from services.replayer.core import ReplayerConfig
from services.replayer.service import ReplayerService
from services.run_log import RunRecorder
from services.scenario import choose_demonstration, model_for
from shared.config import ZenohConfig
from shared.library import MotionLibrary, save_library
from shared.protocol import ClassPosterior, Keys, OccupancyGrid, Plan, RobotState
from shared.scene import load_scene
from shared.synthetic import generate_library
from shared.transport import open_session, subscribe


@dataclasses.dataclass
class SystemFiles:
    """A small synthetic library, the human's demonstration and a model trained without it."""

    library: MotionLibrary
    human: Path
    model: Path
    samples_per_tick: int
    human_class: str


@pytest.fixture(scope="session")
def system_files(tmp_path_factory: pytest.TempPathFactory) -> SystemFiles:
    """Trained once per test session: 8 classes x 6 demonstrations, 4 Gaussians per class."""
    root = tmp_path_factory.mktemp("system")
    lib = generate_library(8, 6, seed=3)
    scenario = choose_demonstration(lib, steps=20, seed=0)
    model = model_for(lib, load_scene(), scenario.demo, root / "models", components=4, progress=False)
    human = root / "human.npz"
    save_library(MotionLibrary(list(lib.class_names), [scenario.demo], [], "test human"), human)
    return SystemFiles(lib, human, model, scenario.samples_per_tick, scenario.demo.class_name)


@dataclasses.dataclass
class System:
    """A running in-process system."""

    hub: ZenohConfig
    keys: Keys
    recorder: RunRecorder
    threads: dict[str, ServiceThread]
    services: dict[str, Any]

    def executor_result(self, timeout: float = 240.0) -> ExecutorResult:
        return self.threads["executor"].join(timeout)


@pytest.fixture
def run_system(system_files: SystemFiles, tmp_path: Path) -> Iterator[Callable[..., System]]:
    """Factory: start the four services in-process; everything is stopped at teardown."""
    started: list[System] = []
    sessions: list[Any] = []

    def start(mode: str = "lockstep", steps: int = 20, seed: int = 0, period: float = 0.2,
              planner_overrides: dict[str, Any] | None = None, executor_overrides: dict[str, Any] | None = None,
              replayer_overrides: dict[str, Any] | None = None, mcap: str = "", security: Path | None = None
              ) -> System:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        secure = {"security_dir": str(security)} if security is not None else {}
        # with security: the test's own session (the hub, which records every key) presents the router's certificate
        hub = ZenohConfig(mode="peer", listen=[endpoint], connect=[], multicast_scouting=False, role="router", **secure)
        base = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], multicast_scouting=False,
                           **secure)

        def peer_as(role: str) -> ZenohConfig:
            return dataclasses.replace(base, role=role)

        keys = Keys(hub.prefix)
        recorder = RunRecorder()
        ctx = open_session(hub)
        session = ctx.__enter__()
        sessions.append(ctx)
        subs = [subscribe(session, keys.plan, Plan, recorder.on_message),
                subscribe(session, keys.robot_state, RobotState, recorder.on_message),
                subscribe(session, keys.occupancy, OccupancyGrid, recorder.on_message),
                subscribe(session, keys.posterior, ClassPosterior, recorder.on_message)]
        sessions.append(subs)
        predictor = PredictorService(PredictorConfig(model=system_files.model), peer_as("predictor"))
        planner_cfg = PlannerServiceConfig(mode=mode, period_s=period, input_timeout_s=20.0,
                                           planner=PlannerConfig(seed=seed, lookahead_s=period, compile=False,
                                                                 stomp=StompConfig(iterations=20),
                                                                 **(planner_overrides or {})))
        planner = PlannerService(planner_cfg, peer_as("planner"))
        replayer = ReplayerService(ReplayerConfig(library=system_files.human, mode=mode,
                                                  samples_per_tick=system_files.samples_per_tick,
                                                  **(replayer_overrides or {})), peer_as("replayer"))
        ex_cfg = ExecutorConfig(mode=mode, steps=steps, step_period_s=period,
                                mcap=mcap or str(tmp_path / f"run{len(started)}.mcap"), lockstep_timeout_s=60.0,
                                **(executor_overrides or {}))
        threads = {
            "predictor": ServiceThread("predictor", predictor.run),
            "planner": ServiceThread("planner", planner.run),
            "replayer": ServiceThread("replayer", replayer.run),
        }
        for t in threads.values():
            t.start()
        ex_stop = threading.Event()
        executor = ExecutorService(ex_cfg, peer_as("executor"), stop=ex_stop)
        threads["executor"] = ServiceThread("executor", lambda _stop: executor.run())
        threads["executor"].stop_event = ex_stop
        threads["executor"].start()
        system = System(hub, keys, recorder, threads,
                        {"predictor": predictor, "planner": planner, "replayer": replayer, "executor": executor})
        started.append(system)
        return system

    yield start
    for system in started:
        for t in system.threads.values():
            t.stop_event.set()
        for t in system.threads.values():
            t.thread.join(JOIN_S)
    for item in reversed(sessions):
        if isinstance(item, list):
            for s in item:
                s.undeclare()
        else:
            item.__exit__(None, None, None)
