"""GraphPeers: whom the gateway leaves the joint states and /clock to; between gateways, the smaller session id."""

from __future__ import annotations

import itertools

from services.ros2.core import TOPICS, Ros2Config
from services.ros2.graph import GraphPeers, PeerChange
from services.ros2.wire import endpoint_token


def _tokens(zid: str, node: str, namespace: str = "/") -> dict[str, str]:
    """A gateway's publisher tokens by role, as its node declares them."""
    cfg = Ros2Config(domain_id=0, node=node, namespace=namespace)
    return {role: endpoint_token(0, zid, 1, i, "MP", cfg.node_namespace, node, cfg.topic(role), t.msgtype,
                                 "RIHS01_x", "q") for i, (role, t) in enumerate(TOPICS.items())}


def test_of_two_gateways_named_apart_the_smaller_session_publishes_whatever_order_the_tokens_come_in() -> None:
    """Named apart (ROS 2 warns of two nodes of one name), each gateway took the other's /clock for a simulator's
    and both went quiet: a lock-step run's ROS 2 nodes saw no time at all (a review)."""
    a, b = _tokens("a1", "foresight_a"), _tokens("b2", "foresight_b", "/cell")
    for order in itertools.permutations(["clock", "joint_states", "posterior"]):
        first = GraphPeers(Ros2Config(domain_id=0, node="foresight_a"), zid="a1")
        second = GraphPeers(Ros2Config(domain_id=0, node="foresight_b", namespace="/cell"), zid="b2")
        for role in order:
            first.update(b[role])
            second.update(a[role])
        assert first.left_to("clock") is None and first.left_to("joint_states") is None  # the smaller: publishes
        assert second.left_to("clock").node == "foresight_a" and second.left_to("joint_states").zid == "a1"


def test_a_simulator_or_driver_is_left_its_topic_and_a_gateway_seen_late_takes_it_back() -> None:
    peers = GraphPeers(Ros2Config(domain_id=0), zid="b2")
    sim = endpoint_token(0, "a1", 1, 2, "MP", "/", "executor_robot", "/clock", "rosgraph_msgs/msg/Clock", "RIHS01_x",
                         "q")
    assert peers.update(sim) == [PeerChange("clock", True, "/executor_robot", "a1", False)]
    assert peers.update(sim, alive=False) == [PeerChange("clock", False, "/executor_robot", "a1", False)]
    assert peers.update(sim.replace("/0/1/2/", "/0/1/3/").replace("/MP/", "/MS/")) == []  # a subscription: no matter
    other = _tokens("c3", "foresight_c")  # a gateway with the larger session id, its /clock token first
    assert peers.update(other["clock"]) == [PeerChange("clock", True, "/foresight_c", "c3", False)]
    assert peers.update(other["goal"]) == [PeerChange("clock", False, "/foresight_c", "c3", True)]  # a gateway
    assert peers.left_to("clock") is None
    assert peers.update(other["joint_states"]) == []  # known now: never left to it
    own = _tokens("b2", "foresight")
    assert all(peers.update(t) == [] for t in own.values())  # its own tokens


def test_roles_the_gateway_does_not_publish_are_no_ones_business() -> None:
    peers = GraphPeers(Ros2Config(domain_id=0, joint_states=False), zid="b2")
    driver = endpoint_token(0, "a1", 1, 2, "MP", "/", "robot_driver", "/joint_states", "sensor_msgs/msg/JointState",
                            "RIHS01_x", "q")
    assert peers.update(driver) == [] and peers.left_to("joint_states") is None


def test_a_real_ros_2_nodes_token_is_read() -> None:
    """A token as rmw_zenoh writes it for ros2_controllers' joint_state_broadcaster (its real QoS field, a 128-bit
    session id), not one made by :func:`endpoint_token`: the tests above would pass with a parser of only our own."""
    token = ("@ros2_lv/0/1f2e3d4c5b6a79881f2e3d4c5b6a7988/0/11/MP/%/%/joint_state_broadcaster/%joint_states/"
             "sensor_msgs::msg::dds_::JointState_/RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e/"
             "::,1:,:,:,,")
    peers = GraphPeers(Ros2Config(domain_id=0), zid="b2")
    change = PeerChange("joint_states", True, "/joint_state_broadcaster", "1f2e3d4c5b6a79881f2e3d4c5b6a7988", False)
    assert peers.update(token) == [change]
    assert peers.left_to("joint_states").topic == "/joint_states"
    assert peers.update(token, alive=False)[0].started is False
