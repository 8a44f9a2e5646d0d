"""The access control is generated from the wire contract's table, and nothing else."""

from __future__ import annotations

import importlib

import pytest

from shared.protocol import HUMAN_SOURCES, ROUTES, SENSOR, SERVICES, Keys
from shared.security.acl import (
    OBSERVER,
    ROLES,
    ROUTER,
    access_control,
    consumed_keys,
    owned_keys,
    remote_roles,
    subscription_exprs,
)
from shared.security.certificates import init_security_dir

KEYS = Keys("cell")


def _rules_of(acl: dict, role: str, message: str, flow: str) -> set[str]:
    ids = next(p["rules"] for p in acl["policies"] if p["subjects"] == [role])
    exprs: set[str] = set()
    for rule in acl["rules"]:
        if rule["id"] in ids and message in rule["messages"] and flow in rule["flows"]:
            assert rule["permission"] == "allow"
            exprs |= set(rule["key_exprs"])
    return exprs


def test_every_data_key_has_its_owners_and_only_the_human_has_two() -> None:
    """A key added to Keys.data_keys without an owner in ROUTES fails here."""
    assert set(ROUTES) == {attr for attr in vars(KEYS) if getattr(KEYS, attr) in KEYS.data_keys()}
    for attr, (owners, consumers) in ROUTES.items():
        assert set(owners) <= {*SERVICES, SENSOR} and set(consumers) <= set(SERVICES), attr
        assert len(owners) == 1 or owners == HUMAN_SOURCES, attr
        assert "executor" in consumers, f"{attr}: the executor logs every key"
    owned = {k for role in (*SERVICES, SENSOR) for k in owned_keys(KEYS, role)}
    assert owned == set(KEYS.data_keys())
    assert set(owned_keys(KEYS, "replayer")) == set(owned_keys(KEYS, "tracker")) == {KEYS.pose, KEYS.demo}
    assert owned_keys(KEYS, SENSOR) == [KEYS.keypoints]


def test_each_role_puts_only_what_it_owns_and_receives_what_it_consumes() -> None:
    acl = access_control(KEYS)
    assert acl["enabled"] and acl["default_permission"] == "deny"
    assert {s["id"]: s["cert_common_names"] for s in acl["subjects"]} == {r: [r] for r in ROLES}
    for role in SERVICES:
        assert _rules_of(acl, role, "put", "ingress") == set(owned_keys(KEYS, role))
        assert _rules_of(acl, role, "put", "egress") == set(consumed_keys(KEYS, role))
        assert _rules_of(acl, role, "liveliness_token", "ingress") == {KEYS.alive(role)}
    assert _rules_of(acl, SENSOR, "put", "ingress") == {KEYS.keypoints}  # keypoints only, no token
    assert _rules_of(acl, SENSOR, "liveliness_token", "ingress") == set()
    assert _rules_of(acl, OBSERVER, "put", "ingress") == set()  # reads only
    assert _rules_of(acl, OBSERVER, "liveliness_token", "ingress") == set()
    assert _rules_of(acl, OBSERVER, "put", "egress") == set(KEYS.data_keys())
    assert _rules_of(acl, ROUTER, "put", "ingress") == set(KEYS.data_keys())  # it forwards


_EVERY = {"keypoints", "pose", "demo", "posterior", "occupancy", "plan", "robot_state", "clock"}
WRITTEN_BY_HAND = {  # role: (keys it may put, keys it may receive); read from services/*/service.py, docs/protocol.md
    "replayer": ({"pose", "demo"}, {"clock"}),  # streams the recording; lock-step paces it by the clock
    "tracker": ({"pose", "demo"}, {"keypoints"}),  # its --from player puts keypoints as the sensor
    "predictor": ({"posterior", "occupancy"}, {"pose", "demo"}),  # foresight/human/*, ordered
    "planner": ({"plan"}, {"pose", "demo", "occupancy", "robot_state", "clock"}),
    "executor": ({"robot_state", "clock"}, _EVERY),  # its MCAP log: foresight/**
    "sensor": ({"keypoints"}, set()),
    "observer": (set(), _EVERY),
    "router": (_EVERY, _EVERY),  # it forwards
}


@pytest.mark.parametrize("role", ROLES)
def test_the_rules_grant_each_role_what_the_services_do(role: str) -> None:
    """A table written from the services' code, not from ROUTES: a wrong derivation of the rules fails here."""
    acl, (puts, receives) = access_control(KEYS), WRITTEN_BY_HAND[role]
    assert _rules_of(acl, role, "put", "ingress") == {getattr(KEYS, k) for k in puts}
    assert _rules_of(acl, role, "put", "egress") == {getattr(KEYS, k) for k in receives}
    subscribe = _rules_of(acl, role, "declare_subscriber", "ingress")
    assert {e for e in subscribe if "*" not in e} == {getattr(KEYS, k) for k in receives}
    assert (KEYS.human_all in subscribe) == ({"pose", "demo"} <= receives)  # the predictor's one ordered stream
    assert ("cell/**" in subscribe) == (receives == _EVERY)
    assert ("cell/prediction/*" in subscribe) == ({"posterior", "occupancy"} <= receives)  # not the planner's
    assert _rules_of(acl, role, "liveliness_token", "ingress") == (
        {KEYS.alive(role)} if role in SERVICES else {KEYS.alive_all} if role == ROUTER else set())


def test_a_client_session_names_its_router_only() -> None:
    every, client = access_control(KEYS, remote_roles("peer")), access_control(KEYS, remote_roles("client"))
    assert remote_roles("router") == remote_roles("peer") == ROLES and remote_roles("client") == (ROUTER,)
    assert [s["id"] for s in client["subjects"]] == [ROUTER] and [p["id"] for p in client["policies"]] == [ROUTER]
    assert client["default_permission"] == "deny"  # any other certificate: nothing either way
    for message, flow in (("put", "ingress"), ("put", "egress"), ("declare_subscriber", "ingress"),
                          ("liveliness_token", "ingress")):
        assert _rules_of(client, ROUTER, message, flow) == _rules_of(every, ROUTER, message, flow)
    assert {r["id"] for r in client["rules"]} == set(client["policies"][0]["rules"])  # no rule left unused
    with pytest.raises(ValueError, match="remotes"):
        access_control(KEYS, ("robot",))


def test_wildcard_subscriptions_only_where_every_matched_key_is_consumed() -> None:
    assert "cell/human/*" in subscription_exprs(KEYS, "predictor")  # poses and markers, one ordered stream
    assert "cell/**" in subscription_exprs(KEYS, "executor")  # its log
    assert "cell/**" not in subscription_exprs(KEYS, "planner")
    assert "cell/human/*" in subscription_exprs(KEYS, "planner")  # poses (real time: its body term), markers
    assert "cell/human/*" not in subscription_exprs(KEYS, "replayer")  # it consumes neither


@pytest.mark.parametrize(("main", "argv", "what"), [
    ("services.ros2.__main__", [], "foresight ros2"),
    ("services.tracker.__main__", ["--input", "ros2"], "foresight tracker --input ros2"),
    ("services.ros2.robot_sim", [], "foresight simrobot"),
    ("services.executor.__main__", ["--robot", "ros2"], "foresight executor --robot ros2"),  # waited, blamed the robot
])
def test_a_command_speaking_ros2_keys_is_refused_under_access_control(tmp_path, capsys, main, argv, what) -> None:
    """It ran and did nothing: the rules drop every key outside the wire contract, without a word."""
    init_security_dir(tmp_path, ROLES)
    with pytest.raises(SystemExit) as stopped:
        importlib.import_module(main).main([*argv, "--security", str(tmp_path)])
    assert stopped.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert f"{what} with --security: ROS 2 keys have no role in the access control yet" in line


@pytest.mark.parametrize("prefix", ["lab/*", "foresight/", "", "/cell"])
def test_acl_for_a_prefix_no_service_takes_is_refused(capsys, prefix) -> None:
    """It printed rules under 'lab/*' (granting every cell) or '/cell' (no key expression) for a zenohd config."""
    from tools.security import main

    with pytest.raises(SystemExit) as stopped:
        main(["acl", "--prefix", prefix])
    assert stopped.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--prefix" in line and "must be a Zenoh key" in line
    assert main(["acl", "--prefix", "lab/cell_2"]) == 0
    assert '"lab/cell_2/planner/plan"' in capsys.readouterr().out
