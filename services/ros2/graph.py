"""Who else publishes the joint states or ``/clock`` on the ROS 2 graph, and which of them the gateway leaves it to.

Pure: fed rmw_zenoh's graph tokens (``@ros2_lv/...``), no Zenoh. Beside a ROS 2 robot its driver publishes the joint
states and, in lock-step, the executor's robot link publishes ``/clock``: the gateway then publishes neither (two
sources would take turns). Another Foresight gateway is different: it would step back for this one as this one for
it, and neither would publish (a lock-step run's ROS 2 nodes saw no time at all). Between gateways the one with the
smaller Zenoh session id publishes. A gateway is a node named as this one, or one whose session publishes one of
Foresight's own topics (``<its namespace>/foresight/...`` of Foresight's type): two gateways are usually named
apart (``--node foresight_a``, ``foresight_b``), as ROS 2 warns of two nodes of one name, and so named, each took
the other for a simulator and both went quiet (a review, 2026-11-29).
"""

from __future__ import annotations

from dataclasses import dataclass

from .core import TOPICS, Ros2Config, namespaced
from .wire import Endpoint, dds_type, parse_endpoint_token

__all__ = ["GraphPeers", "PeerChange", "DEFERRED_ROLES", "node_name"]

DEFERRED_ROLES = ("joint_states", "clock")
"""The roles the gateway leaves to another node that publishes them."""

_OWN = [(t.name, dds_type(t.msgtype)) for t in TOPICS.values() if not t.name.startswith("/")]
"""Foresight's own topics (relative to a gateway's namespace) and their types: a session publishing one is a gateway."""


@dataclass(frozen=True)
class PeerChange:
    """The gateway starts (``started``) or stops leaving ``role``'s topic to ``node`` (another gateway: ``gateway``)."""

    role: str
    started: bool
    node: str
    zid: str
    gateway: bool


class GraphPeers:
    """The other publishers of the deferred roles' topics, and the one the gateway leaves each role to.

    Args:
        config: The gateway's options (its node name, its topics, which roles it publishes at all).
        zid: This gateway's session id (its own tokens are not others').
    """

    def __init__(self, config: Ros2Config, zid: str = "") -> None:
        self.config, self.zid = config, zid
        self._publishers: dict[str, dict[str, Endpoint]] = {r: {} for r in DEFERRED_ROLES}  # role -> token -> it
        self._gateways: dict[str, set[str]] = {}  # session id -> its tokens of Foresight's own topics

    def is_gateway(self, ep: Endpoint) -> bool:
        """Whether ``ep``'s node is another Foresight gateway (named as this one, or publishing Foresight's topics)."""
        return ep.node == self.config.node or ep.zid in self._gateways

    def left_to(self, role: str) -> Endpoint | None:
        """The publisher ``role``'s topic is left to (None: the gateway publishes it)."""
        return next((ep for ep in self._publishers[role].values()
                     if not (self.is_gateway(ep) and ep.zid > self.zid)), None)

    def update(self, key: str, alive: bool = True) -> list[PeerChange]:
        """A graph token came (``alive``) or went; what it changed about whom each role is left to."""
        ep = parse_endpoint_token(key)
        if ep is None or ep.kind != "MP" or ep.zid == self.zid:
            return []
        before = {r: self.left_to(r) for r in DEFERRED_ROLES}
        if any(ep.topic == namespaced(ep.namespace, name) and ep.type_name == kind for name, kind in _OWN):
            tokens = self._gateways.setdefault(ep.zid, set())
            tokens.add(key) if alive else tokens.discard(key)
            if not tokens:
                del self._gateways[ep.zid]
        role = next((r for r in DEFERRED_ROLES if ep.topic == self.config.topic(r) and self.config.enabled(r)), None)
        if role is not None:
            if alive:
                self._publishers[role][key] = ep
            else:
                self._publishers[role].pop(key, None)
        changes = []
        for r in DEFERRED_ROLES:
            after = self.left_to(r)
            if (before[r] is None) != (after is None):
                other = after or before[r]
                changes.append(PeerChange(r, after is not None, node_name(other), other.zid, self.is_gateway(other)))
        return changes


def node_name(ep: Endpoint) -> str:
    """The endpoint's node as ROS 2 writes it: ``/namespace/name`` (``/name`` in the root namespace)."""
    return f"{ep.namespace.rstrip('/')}/{ep.node}"
