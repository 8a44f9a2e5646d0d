"""The services a demo runs, in which order, and each one's command line for the demo's scenario.

:func:`service_options` is the one source of every service's own flags: the demo passes them on the command line
(:func:`service_args`, with the Zenoh ones), ``foresight demo --prepare`` writes them as each service's config
section (:mod:`services.demo_prepare`), and compose.yaml runs that.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from services.view.config import DEFAULT_PORT
from shared.config import ZenohConfig, load_toml
from shared.config_names import section_class
from shared.config_tree import ENV_PREFIX, Option, config_options

if TYPE_CHECKING:
    from services.demo import DemoConfig

__all__ = ["SERVICES_IN_ORDER", "KEYPOINTS_FILE", "KEYPOINT_REST_S", "RUN", "NO_HUMAN_COST", "MODULES",
           "services_in_order", "extra_services", "service_args", "service_options", "demo_set_options", "DEMO_ZENOH"]


SERVICES_IN_ORDER = ("predictor", "planner", "replayer", "executor")
"""Start order: the executor (simulation master) last, once the others listen."""

KEYPOINTS_FILE = "human-keypoints.csv"
"""``--human keypoints``: the human's demonstration as a keypoint recording, in the run's directory."""

KEYPOINT_REST_S = 1.5
"""``--human keypoints``: seconds the person stands still before and after the reach in the recording."""


def services_in_order(cfg: DemoConfig) -> tuple[str, ...]:
    """The demo's four services in start order, the tracker in the replayer's place with ``--human keypoints``."""
    return tuple("tracker" if s == "replayer" and cfg.human == "keypoints" else s for s in SERVICES_IN_ORDER)


def extra_services(cfg: DemoConfig) -> tuple[str, ...]:
    """The services this demo runs besides its four: the ROS 2 gateway (``--ros2``) and its simulated robot."""
    return (*(("ros2",) if cfg.ros2 else ()), *(("simrobot",) if cfg.robot == "ros2-sim" else ()))


DEMO_ZENOH = ("mode", "listen", "connect", "prefix", "security_dir", "role")
"""The ``[zenoh]`` options the demo decides for every service: its own router on loopback, its ``--prefix`` and
``--security``."""


def demo_set_options(cfg: DemoConfig) -> dict[str, list[Option]]:
    """Each section's options this demo sets on its services' command lines, which a file or a variable cannot change.

    The services read the demo's config file and the environment (``FORESIGHT_CONFIG``), and a flag beats both:
    ``[replayer] rate_hz = 10`` in ``foresight demo --config FILE`` gave a replayer at the demo's 30 Hz, no word.
    """
    flags = service_options(cfg, Path("model"), Path("library"), 1, None)  # the flags' names do not hang on paths
    out: dict[str, list[Option]] = {}
    for name in (*services_in_order(cfg), *extra_services(cfg)):
        given = {a for a in flags[name] if a.startswith("--")}
        out[name] = [o for o in config_options(name, section_class(name))
                     if o.flag in given or f"--no-{o.flag[2:]}" in given]
    out["zenoh"] = [o for o in config_options("zenoh", ZenohConfig) if o.field in DEMO_ZENOH]
    return out


MODULES = {"simrobot": "services.ros2.robot_sim"}
"""Services whose module is not ``services.<name>``."""


def service_args(cfg: DemoConfig, endpoint: str, model: Path, replay_library: Path, samples_per_tick: int,
                 mcap: Path) -> dict[str, list[str]]:
    """Command-line arguments of each service for this demo."""
    common = ["--connect", endpoint, "--listen", "tcp/127.0.0.1:0", "--prefix", cfg.prefix, "--zenoh-mode", "peer",
              *(["--security", str(cfg.security)] if cfg.security else [])]
    own = service_options(cfg, model, replay_library, samples_per_tick, mcap)
    return {name: [*flags, *common, *_log_level(name, cfg.log_level)] for name, flags in own.items()}


def _log_level(service: str, demo_level: str) -> list[str]:
    """A service's ``--log-level``: INFO into its log, DEBUG with the demo's; none where the user set its own.

    ``FORESIGHT_PLANNER_LOG_LEVEL=DEBUG foresight demo`` gave the planner's per-plan lines nowhere: a flag beats the
    variable, and the demo passed INFO to every service.
    """
    if os.environ.get(f"FORESIGHT_{service.upper()}_LOG_LEVEL"):
        return []
    path = os.environ.get(f"{ENV_PREFIX}_CONFIG")  # the demo's config file, given to the services: its level too
    if path and "log_level" in load_toml(path).get(service, {}):
        return []
    return ["--log-level", "DEBUG" if demo_level.upper() == "DEBUG" else "INFO"]


RUN = "predictor,planner,executor"
"""What a real-time human source waits for before it plays: with the executor alone, services started by hand
(docs/keypoints.md) had the whole reach played while the planner was still starting, and the robot ran against
no human."""


NO_HUMAN_COST = ("--cost.w-human", "0", "--cost.body-clearance", "0")
"""The planner's flags of the paper's basic STOMP (``--human-cost false``): no cost for the person at all, neither the
predicted occupancy nor, in real time, the body as last seen (``services.planner.body``)."""


def _lockstep_stale_limit(cfg: DemoConfig) -> list[str]:
    """The executor's ``--stale-limit-s`` for a lock-step period above its default limit (else none).

    Every plan is a period old when adopted: ``--period-s 0.6`` held the robot at every step.
    """
    import dataclasses

    from services.executor.config import ExecutorConfig, lockstep_stale_limit

    default = next(f.default for f in dataclasses.fields(ExecutorConfig) if f.name == "stale_limit_s")
    limit = lockstep_stale_limit(cfg.period_s, float(default))  # type: ignore[arg-type]
    return ["--stale-limit-s", f"{limit:g}"] if cfg.mode == "lockstep" and limit != default else []


def service_options(cfg: DemoConfig, model: Path, replay_library: Path, samples_per_tick: int,
                    mcap: Path | None) -> dict[str, list[str]]:
    """Each service's own options (flags, no Zenoh ones) for this demo's scenario; ``mcap`` None: the default."""
    scene = ["--scene", cfg.scene] if cfg.scene else []
    lockstep = cfg.mode == "lockstep"
    return {
        "predictor": ["--model", str(model), "--method", cfg.method, *scene],
        "planner": ["--mode", cfg.mode, "--seed", str(cfg.seed), "--period-s", str(cfg.period_s),
                    "--velocity-scale", str(cfg.robot_speed), *(["--goals", cfg.goals] if cfg.goals else []),
                    "--lookahead-s", str(cfg.period_s), *([] if cfg.human_cost else NO_HUMAN_COST), *scene],
        "replayer": ["--library", str(replay_library), "--mode", cfg.mode,  # each mode's own pace option only
                     *(["--samples-per-tick", str(samples_per_tick)] if lockstep
                       else ["--rate-hz", str(cfg.rate_hz), "--wait-for", RUN])],
        "tracker": ["--from-file", str(Path(replay_library).parent / KEYPOINTS_FILE), "--rate-hz", str(cfg.rate_hz),
                    "--lead-s", "0", "--hold-s", "0", "--wait-for", RUN],  # the rest is in the recording
        "ros2": [*scene, *([] if cfg.robot == "sim" else ["--no-joint-states"])],  # a ROS 2 robot has its own
        "simrobot": [*scene, "--sim-time" if lockstep else "--no-sim-time"],
        "view": ["--port", str(cfg.live or DEFAULT_PORT), *scene],
        "executor": ["--mode", cfg.mode, "--steps", str(cfg.steps), "--step-period-s", str(cfg.period_s),
                     *_lockstep_stale_limit(cfg),
                     *(["--wait-for", "tracker,predictor,planner", "--recorded-sources", "replayer,tracker"]
                       if cfg.human == "keypoints" else []),  # its tracker plays a file: the file's end is no fault
                     *([] if cfg.robot == "sim" else ["--robot", "ros2"]),
                     *(["--finish-path"] if lockstep and cfg.finish else []),
                     *(["--finish-s", f"{cfg.finish_s:g}"] if cfg.finish_s else []),
                     *(["--live-port", str(cfg.live)] if cfg.live else []),
                     *(["--mcap", str(mcap)] if mcap is not None else []), *scene],
    }
