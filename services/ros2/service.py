"""The ``ros2`` service's loop: Foresight's messages in, ROS 2 samples out on rmw_zenoh keys, with the graph tokens.

A ROS 2 node named ``config.node`` (liveliness token ``NN``), one publisher token (``MP``) per topic,
and per published sample the rmw_zenoh attachment (per-topic sequence number from 1, source time,
the publisher's 16-byte GID). The occupancy and the human are markers for RViz and are sent at most
``viz_rate_hz`` times a second each (encoding thousands of points is not free): one that comes sooner is
held, replaced by any newer one, and sent when its window has passed, so the newest is always shown; the
plan, goal, joint states and posterior go out as they come.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from shared.config import ConfigError, ZenohConfig, opt
from shared.config_names import check_services
from shared.human import StreamPlacement
from shared.protocol import (
    SERVICES,
    ClassPosterior,
    ClockTick,
    DemoMarker,
    Expectations,
    HumanPose,
    Keys,
    OccupancyGrid,
    Plan,
    Receipt,
    RobotState,
)
from shared.rejects import RejectCounter
from shared.scene import SCENE_HELP, load_scene
from shared.transport import Presence, open_session, subscribe

from .core import TOPICS, Ros2Config, Ros2Mapping
from .graph import GraphPeers, node_name
from .node import Ros2Node, Ros2Publisher

__all__ = ["Ros2ServiceConfig", "Ros2Service", "Ros2Stats"]

log = logging.getLogger("foresight.ros2")
_MIN_FLUSH_WAIT_S = 0.005
"""The held-back markers' flush loop sleeps at least this long: a very high ``viz_rate_hz`` (1e12 for "no limit")
spun a core with no message flowing."""


@dataclass
class Ros2ServiceConfig(Ros2Config):
    """Options of ``foresight ros2``: the mapping's and the loop's."""

    scene: str = opt("", help=SCENE_HELP + " (places the human's markers; empty: pr2_two_cups)")
    viz_rate_hz: float = opt(5.0, help="highest rate of the occupancy and human markers per topic")
    stop_with: list[str] = opt(default_factory=list, help="stop when one of these services (e.g. executor) "
                               "disappears after it was seen (comma-separated, as the other services')")
    nice: int = opt(10, help="`foresight ros2` lowers its CPU priority by this much (0-19): encoding markers must "
                    "not take CPU from the planning loop on a shared machine")

    def validate(self) -> None:
        """Check ranges and names."""
        super().validate()
        if not 0 <= self.nice <= 19:
            raise ConfigError(f"ros2.nice: must be 0..19, got {self.nice}")
        if not self.viz_rate_hz > 0:
            raise ConfigError(f"ros2.viz_rate_hz: must be > 0, got {self.viz_rate_hz}")
        # misspelt, a service is never seen go, and the gateway runs on without a word
        check_services(self.stop_with, "ros2.stop_with", SERVICES)


@dataclass
class Ros2Stats:
    """What the gateway sent, per ROS 2 topic."""

    sent: dict[str, int]


class Ros2Service:
    """Publishes Foresight's run as ROS 2 topics over rmw_zenoh (no ROS installation needed).

    Args:
        config: Topics, frame, rates.
        zenoh: The session's config (the same Zenoh network as the ROS 2 nodes: their rmw_zenoh router).
    """

    def __init__(self, config: Ros2ServiceConfig, zenoh: ZenohConfig) -> None:
        config.validate()
        self.config = config
        self.zenoh = zenoh
        self.keys = Keys(zenoh.prefix)
        self.mapping = Ros2Mapping(config)
        self.scene = load_scene(config.scene or None)
        self.rejects = RejectCounter("ros2", known_keys=self.keys.data_keys())
        self.receipt = Receipt(Expectations(clock="auto"))  # values, stamps and each sender's order, as any service
        self.stats = Ros2Stats({role: 0 for role in TOPICS})
        self._lock = threading.Lock()
        self._clock_lock = threading.Lock()  # /clock samples leave in the order their times were taken
        self._pubs: dict[str, Ros2Publisher] = {}
        self._placement = StreamPlacement(self.scene)  # the human's, as the predictor places it
        self._last_viz: dict[str, float] = {}
        self._pending: dict[str, Callable[[], bytes]] = {}  # role -> the newest marker held back by the rate limit
        self._peers = GraphPeers(config)  # other nodes publishing the joint states or /clock (a robot's driver, ...)
        self._sim_time: float | None = None  # the lock-step run's simulated time (None: no ClockTick seen, real time)
        self._zid = ""

    def _put(self, role: str, payload: bytes) -> None:
        pub = self._pubs.get(role)
        if pub is not None:
            pub.put(payload)
            self.stats.sent[role] = pub.sent

    def _viz(self, role: str, make: Callable[[], bytes]) -> None:
        """Send a marker now, or hold it (encoded later) until its rate window has passed; a newer one replaces it."""
        now = time.monotonic()
        with self._lock:
            if now - self._last_viz.get(role, -1e9) < 1.0 / self.config.viz_rate_hz:
                self._pending[role] = make
                return
            self._last_viz[role] = now
            self._pending.pop(role, None)
        self._put(role, make())

    def flush_viz(self, force: bool = False) -> None:
        """Send each held marker whose window has passed (all of them with ``force``): the newest is never lost.

        Without this, RViz kept showing an older occupancy or body when the stream paused or ended.
        """
        now = time.monotonic()
        with self._lock:
            due = [(r, m) for r, m in self._pending.items()
                   if force or now - self._last_viz.get(r, -1e9) >= 1.0 / self.config.viz_rate_hz]
            for r, _ in due:
                del self._pending[r]
                self._last_viz[r] = now
        for role, make in due:
            self._put(role, make())

    def on_plan(self, plan: Plan) -> None:
        """The chosen trajectory and goal."""
        self._put("trajectory", self.mapping.trajectory(plan))
        self._put("goal", self.mapping.goal(plan))

    @property
    def robot_publishes(self) -> str | None:
        """A node other than the gateway publishing the joint states topic (a robot's driver), or None."""
        return self.publishes("joint_states")

    def publishes(self, role: str) -> str | None:
        """A node other than the gateway publishing ``role``'s topic (``joint_states`` or ``clock``), or None."""
        with self._lock:
            ep = self._peers.left_to(role)
        return None if ep is None else node_name(ep)

    def on_state(self, state: RobotState) -> None:
        """The simulated robot's joints (not when another node publishes the joint states: :meth:`on_graph`).

        In a lock-step run its stamp also advances ``/clock`` (:meth:`on_tick`): the states come every state
        period, the ticks every replanning step.
        """
        if self.config.joint_states and self.publishes("joint_states") is None:
            self._put("joint_states", self.mapping.joint_state(state))
        if state.tick < 0:  # a real-time state: no simulated time (a gateway that saw a lock-step run before sent
            with self._lock:  # the wall clock on /clock)
                self._sim_time = None
        elif self._sim_time is not None:
            self._advance_clock(state.stamp)

    def on_tick(self, tick: ClockTick) -> None:
        """A lock-step clock tick: the run's time is simulated, from 0, and ``/clock`` says it.

        Before, a lock-step run's messages went out stamped 1970-01-01 plus a few seconds, with no ``/clock``: a
        ROS 2 node on the wall clock (RViz by default) saw them 56 years old, and one with ``use_sim_time`` never
        saw time pass. Not in real time (no ticks; the stamps are the wall clock's), nor while another node
        publishes ``/clock`` (the executor's ROS 2 robot link, a simulator: :meth:`on_graph`).
        """
        if tick.tick == 0:  # a new run: its time starts again (ROS 2 nodes reset on a jump back)
            with self._lock:
                self._sim_time = None
        if self._sim_time is None:
            other = self.publishes("clock")
            log.info("ros2: a lock-step run (clock tick %d at %.3f s): its simulated time goes out on %s%s; ROS 2 "
                     "nodes follow it with use_sim_time", tick.tick, tick.stamp, self.config.topic("clock"),
                     f" (from {other})" if other else "" if self.config.clock else " (not from here: --no-clock)")
        self._advance_clock(tick.stamp)

    def _advance_clock(self, t: float) -> None:
        """Publish ``/clock`` = ``t`` s if it is later than the last (a clock never goes back).

        One at a time: a tick and a state (two subscriber threads) each took their time under the lock and sent it
        after, so the later could go out first and the clock stepped back on the wire.
        """
        with self._clock_lock:
            with self._lock:
                if self._sim_time is not None and t <= self._sim_time:
                    return
                self._sim_time = t
            if self.config.clock and self.publishes("clock") is None:
                self._put("clock", self.mapping.clock(t))

    def on_graph(self, key: str, alive: bool = True) -> None:
        """A graph token (``alive`` False: withdrawn): another node publishing the joint states or ``/clock``.

        The executor driving a ROS 2 robot (``robot = "ros2"``) publishes the robot's measured joints as its
        RobotState; echoed onto the robot's own topic they came back as a second publisher's states (116 refused
        by the executor in a review run, the rest taken for fresh measurements). While another node publishes
        there the gateway publishes no joint states, and says so when that starts and ends. The same for
        ``/clock``: beside a ROS 2 robot in lock-step the executor publishes the simulated time itself, at every
        state period, and two clocks would take turns. Between two gateways the one with the smaller session id
        publishes (:mod:`services.ros2.graph`).
        """
        with self._lock:
            changes = self._peers.update(key, alive)
        for c in changes:
            topic = self.config.topic(c.role)
            if c.started and c.gateway:
                log.info("ros2: node %s (session %s), another gateway, publishes %s too: the one with the smaller "
                         "session id publishes it, not this one", c.node, c.zid, topic)
            elif c.started:  # the joint states: a setting to change; the clock: as it should be beside a ROS 2 robot
                what = ("(a robot's driver): the executor's RobotState is not echoed there (run the gateway with "
                        "--no-joint-states beside a ROS 2 robot)" if c.role == "joint_states" else
                        "(a simulator, the executor's ROS 2 robot link): the gateway publishes no simulated time there")
                log.log(logging.WARNING if c.role == "joint_states" else logging.INFO, "ros2: node %s publishes %s %s",
                        c.node, topic, what)
            elif c.gateway and c.zid > self._zid:  # its Foresight topics came after its /clock: a gateway after all
                log.info("ros2: node %s (session %s) is another gateway, with the larger session id: this one "
                         "publishes %s", c.node, c.zid, topic)
            else:
                log.info("ros2: no other node publishes %s now; the gateway publishes it again", topic)

    def on_occupancy(self, grid: OccupancyGrid) -> None:
        """The predicted occupancy (rate-limited)."""
        self._viz("occupancy", lambda: self.mapping.occupancy(grid))

    def on_human(self, msg: HumanPose | DemoMarker) -> None:
        """The human's body, placed as the predictor places it (relative to the demonstration's first pose)."""
        if isinstance(msg, DemoMarker):
            return
        placed = self._placement.place(msg.demo_id, msg.index, msg.features)
        self._viz("human", lambda: self.mapping.human(msg, placed))

    def on_posterior(self, post: ClassPosterior) -> None:
        """The class posterior."""
        self._put("posterior", self.mapping.posterior(post))

    def run(self, stop: threading.Event | None = None) -> Ros2Stats:
        """Serve until ``stop`` is set (or the ``stop_with`` service goes away)."""
        stop = stop or threading.Event()
        cfg = self.config
        with open_session(self.zenoh, stop, "ros2") as session:
            node = Ros2Node(session, cfg.domain_id, cfg.node_namespace, cfg.node, self.mapping.hashes, self.rejects)
            zid = self._zid = self._peers.zid = node.zid

            def on_token(sample: zenoh.Sample) -> None:
                self.on_graph(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

            graph = session.liveliness().declare_subscriber(f"@ros2_lv/{cfg.domain_id}/**", on_token, history=True)
            for role, topic in TOPICS.items():
                if cfg.enabled(role):
                    self._pubs[role] = node.publisher(cfg.topic(role), topic.msgtype)
            k = self.keys
            subs = [subscribe(session, key, cls, handler, self.rejects, self.receipt) for key, cls, handler in (
                (k.plan, Plan, self.on_plan), (k.robot_state, RobotState, self.on_state),
                (k.occupancy, OccupancyGrid, self.on_occupancy), (k.posterior, ClassPosterior, self.on_posterior),
                (k.pose, HumanPose, self.on_human), (k.clock, ClockTick, self.on_tick))]
            presence = Presence(session, self.keys, "ros2", stop_with=cfg.stop_with, stop=stop)
            log.info("ros2: node %s%s on domain %d, topics %s, session %s", cfg.node_namespace.rstrip("/") + "/",
                     cfg.node, cfg.domain_id, ", ".join(cfg.topic(r) for r in TOPICS), zid)
            try:
                while not stop.wait(max(0.5 / cfg.viz_rate_hz, _MIN_FLUSH_WAIT_S)):
                    self.flush_viz()
            finally:
                self.flush_viz(force=True)  # the last occupancy and body stay on show
                presence.close()
                graph.undeclare()
                for s in subs:
                    s.undeclare()
                node.close()
        sent = ", ".join(f"{cfg.topic(r)} {n}" for r, n in self.stats.sent.items())
        log.info("ros2: stopped; sent %s; refused %s", sent, self.rejects.summary())
        return self.stats
