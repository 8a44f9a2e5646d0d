"""The ``view`` loop: subscribe to a running system's messages, serve its scene live on ws://HOST:PORT.

It subscribes to the plan, robot state, occupancy, posterior, human pose, demonstration-marker and keypoint keys (as
the read-only ``observer`` when security is on: it puts nothing and declares no token) and logs each message's scene to
a :class:`~shared.foxglove.live.LiveServer`, which sends the static scene again every ``static_period_s``
for clients that connect later.
"""

from __future__ import annotations

import logging
import resource
import threading

from shared.config import ZenohConfig
from shared.foxglove.live import LiveServer
from shared.foxglove.scene import default_builder
from shared.protocol import (
    ClassPosterior,
    DemoMarker,
    Expectations,
    HumanKeypoints,
    HumanPose,
    Keys,
    Message,
    OccupancyGrid,
    Plan,
    Receipt,
    RobotState,
)
from shared.rejects import RejectCounter
from shared.runtime import wait_for_stop
from shared.scene import load_scene
from shared.transport import open_session, subscribe, subscribe_ordered

from .config import ViewConfig
from .core import ViewCore

__all__ = ["ViewConfig", "ViewService"]

log = logging.getLogger("foresight.view")


class ViewService:
    """Serves a running system's scene live to the Foxglove app.

    Args:
        config: Port, scene, rates.
        zenoh: The session's config (the system's router; role observer under security).
    """

    def __init__(self, config: ViewConfig, zenoh: ZenohConfig) -> None:
        config.validate()
        self.config = config
        self.zenoh = zenoh
        self.keys = Keys(zenoh.prefix)
        self.scene = load_scene(config.scene or None)
        self.core = ViewCore(default_builder(self.scene, config.device),
                             viz_period_s=1.0 / config.viz_rate_hz)
        self.rejects = RejectCounter("view", known_keys=self.keys.data_keys())
        self.receipt = Receipt(Expectations(clock="auto"))  # values, stamps and each sender's order, as any service
        self.server: LiveServer | None = None
        self.failures = 0

    def _on(self, msg: Message) -> None:
        server = self.server
        if server is None:
            return
        try:
            for m in self.core.on_message(msg, server.watched):  # nobody watching: no drawing (FK, encoding)
                server.log(m)
        except Exception:  # a drawing bug costs a picture, never the view
            self.failures += 1
            if self.failures == 1 or self.failures % 100 == 0:
                log.exception("view: drawing or sending a %s failed (%d so far)", msg.TYPE, self.failures)

    def run(self, stop: threading.Event | None = None) -> dict[str, int]:
        """Serve until ``stop`` is set; returns the messages sent per topic."""
        stop = stop or threading.Event()
        cfg = self.config
        with (LiveServer(cfg.port, cfg.host, static=lambda _now: self.core.static(),
                         static_period_s=cfg.static_period_s) as server,
              open_session(self.zenoh, stop, "view") as session):
            self.server = server
            k = self.keys
            subs = [subscribe(session, key, cls, self._on, self.rejects, self.receipt)
                    for key, cls in ((k.plan, Plan), (k.robot_state, RobotState), (k.occupancy, OccupancyGrid),
                                     (k.posterior, ClassPosterior), (k.keypoints, HumanKeypoints))]
            # poses and markers in one ordered stream: on two subscriptions (two Zenoh threads) a reach's end marker
            # was often drawn before its last pose, which drew the body as still reaching (the predictor's way too)
            subs.append(subscribe_ordered(session, k.human_all, {k.pose: HumanPose, k.demo: DemoMarker}, self._on,
                                          self.rejects, self.receipt))
            log.info("view: serving %s to the Foxglove app (Open connection -> Foxglove WebSocket; layout: "
                     "docs/foresight.foxglove.json); prefix %r", server.url, self.zenoh.prefix)
            print(f"foresight view: watch live at {server.url}; drawing scene {self.scene.name} (--scene: the "
                  "system's own, e.g. pr2_two_cups_side for foresight demo and docker compose)", flush=True)
            try:
                wait_for_stop(stop)
            finally:
                self.server = None
                for s in subs:
                    s.undeclare()
        sent = {t: n for t, n in server.sent.items() if n}
        usage = resource.getrusage(resource.RUSAGE_SELF)
        log.info("view: stopped; sent %s; rejected %s; %s; CPU %.2f s (user %.2f, system %.2f)",
                 ", ".join(f"{t} {n}" for t, n in sent.items()) or "nothing", self.rejects.summary(),
                 f"drawing failed {self.failures} times (the first logged above)" if self.failures else
                 "no drawing failed", usage.ru_utime + usage.ru_stime, usage.ru_utime, usage.ru_stime)
        return sent


