"""services.ros2.node on a real loopback session: graph ids unique per session, a failing handler counted."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from services.ros2.core import Ros2Config, Ros2Mapping
from services.ros2.node import Ros2Node, next_entity_id
from services.ros2.wire import Attachment, data_key, endpoint_gid, qos_chunk
from shared.config import ZenohConfig
from shared.rejects import RejectCounter
from shared.transport import open_session

STRING = "std_msgs/msg/String"


def _tokens(session, domain: int) -> list[str]:
    return sorted(str(r.ok.key_expr) for r in session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=2.0) if r.ok)


def test_ids_count_per_session_from_zero() -> None:
    assert [next_entity_id("test-a") for _ in range(3)] == [0, 1, 2]
    assert next_entity_id("test-b") == 0 and next_entity_id("test-a") == 3


def test_two_nodes_on_one_session_have_distinct_tokens_and_gids(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool]) -> None:
    hashes = Ros2Mapping(Ros2Config()).hashes
    with open_session(zenoh_hub()) as session, open_session(zenoh_hub()) as graph:
        nodes = [Ros2Node(session, 7, "/", name, hashes, RejectCounter("test")) for name in ("one", "two")]
        try:
            pubs = [n.publisher("/joint_states", "sensor_msgs/msg/JointState") for n in nodes]
            assert nodes[0].node_id != nodes[1].node_id
            assert pubs[0].gid != pubs[1].gid
            assert wait_until(lambda: len(_tokens(graph, 7)) == 4, 10.0), _tokens(graph, 7)
            tokens = _tokens(graph, 7)
            ids = {tuple(t.split("/")[3:5]) for t in tokens}  # (node id, entity id) of each token
            assert len(ids) == 4, tokens
        finally:
            for n in nodes:
                n.close()


def test_a_handler_that_fails_is_logged_counted_and_the_node_goes_on(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool], caplog) -> None:
    mapping = Ros2Mapping(Ros2Config())
    rejects = RejectCounter("test")
    handled: list[bytes] = []
    lock = threading.Lock()

    def handler(payload: bytes) -> None:
        if payload.endswith(b"boom"):
            raise KeyError("boom")  # a receiver's bug, not a malformed sample
        with lock:
            handled.append(payload)

    with open_session(zenoh_hub()) as session, open_session(zenoh_hub()) as other:
        node = Ros2Node(session, 3, "/", "listener", mapping.hashes, rejects)
        talker = Ros2Node(other, 3, "/", "talker", mapping.hashes, RejectCounter("talker"))
        try:
            node.subscription("/chatter", STRING, handler)
            pub = talker.publisher("/chatter", STRING)
            with caplog.at_level(logging.ERROR, logger="foresight.ros2"):
                assert wait_until(lambda: (pub.put(b"boom"), rejects.by_reason)[1].get(("/chatter", "handler"), 0) >= 1,
                                  10.0)
                pub.put(b"fine")
                assert wait_until(lambda: b"fine" in handled, 10.0)
            assert set(rejects.by_reason) == {("/chatter", "handler")}  # not refused as malformed or attachment
            assert any("handling a std_msgs/msg/String sample on /chatter failed unexpectedly" in r.getMessage()
                       and r.exc_info for r in caplog.records)
        finally:
            node.close()
            talker.close()


class _Sample:
    """A Zenoh sample as the node's callback reads it: key, payload and rmw_zenoh's attachment."""

    class _Bytes:
        def __init__(self, data: bytes) -> None:
            self.data = data

        def to_bytes(self) -> bytes:
            return self.data

    def __init__(self, key: str, payload: bytes, seq: int) -> None:
        self.key_expr = key
        self.payload = self._Bytes(payload)
        self.attachment = self._Bytes(Attachment(seq, time.time_ns(), bytes(16)).encode())


def test_a_handler_failing_on_every_sample_is_counted_each_time_with_one_traceback(
        zenoh_hub: Callable[[], ZenohConfig], caplog) -> None:
    """Each failing sample logged its traceback: a publisher at 30 Hz, 30 tracebacks a second (a review)."""
    mapping = Ros2Mapping(Ros2Config())
    rejects = RejectCounter("test")

    def handler(payload: bytes) -> None:
        raise KeyError("a receiver's bug")

    with open_session(zenoh_hub()) as session:
        node = Ros2Node(session, 3, "/", "listener", mapping.hashes, rejects)
        try:
            node.subscription("/chatter", STRING, handler)
            key = data_key(3, "/chatter", STRING, mapping.hashes[STRING])
            with caplog.at_level(logging.WARNING):
                for seq in range(1, 101):
                    node._on_sample(_Sample(key, b"boom", seq))
        finally:
            node.close()
    assert rejects.by_reason == {("/chatter", "handler"): 100}
    assert sum(1 for r in caplog.records if r.exc_info) == 1


def test_a_publishers_gid_is_rmw_zenohs_for_its_token(
        zenoh_hub: Callable[[], ZenohConfig], wait_until: Callable[..., bool]) -> None:
    """The GID was sha256(zid/entity): a subscriber got one that `ros2 topic info -v` never shows.

    rmw_zenoh parses a token, writes it again (QoS defaults blank) and hashes that: the GID of the token as seen.
    """
    hashes = Ros2Mapping(Ros2Config()).hashes
    with open_session(zenoh_hub()) as session, open_session(zenoh_hub()) as graph:
        node = Ros2Node(session, 9, "/", "talker", hashes, RejectCounter("test"))
        try:
            pub = node.publisher("/joint_states", "sensor_msgs/msg/JointState")
            assert wait_until(lambda: any("/MP/" in t for t in _tokens(graph, 9)), 10.0)
            token = next(t for t in _tokens(graph, 9) if "/MP/" in t)
            prefix, _, qos = token.rpartition("/")
            assert qos == qos_chunk(depth=10)  # declared in full
            assert pub.gid == endpoint_gid(f"{prefix}/{qos_chunk(depth=10, explicit=False)}")
        finally:
            node.close()


def test_a_humble_sample_is_refused_as_humbles_not_as_another_definition(
        zenoh_hub: Callable[[], ZenohConfig], caplog) -> None:
    mapping = Ros2Mapping(Ros2Config())
    rejects = RejectCounter("test")
    with open_session(zenoh_hub()) as session:
        node = Ros2Node(session, 3, "/", "listener", mapping.hashes, rejects)
        try:
            node.subscription("/chatter", STRING, lambda payload: None)
            key = data_key(3, "/chatter", STRING, "TypeHashNotSupported")
            with caplog.at_level(logging.WARNING):
                node._on_sample(_Sample(key, b"hi", 1))
        finally:
            node.close()
    assert rejects.by_reason == {("/chatter", "type"): 1}
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "a ROS 2 Humble node (rmw_zenoh on Humble sends no type hash): not supported, docs/ros2.md" in text, text
    assert "another definition" not in text
