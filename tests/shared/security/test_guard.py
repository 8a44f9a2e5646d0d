"""A secure session says, at declaration, what the access control will drop (one line, the service goes on)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from services.processes import free_port
from shared.config import ConfigError, ZenohConfig
from shared.protocol import ClassPosterior, Keys, RobotState
from shared.security.acl import ROLES
from shared.security.certificates import init_security_dir
from shared.security.guard import denied, forget, remember
from shared.security.tls import insecure_listen_warning, secure_endpoints
from shared.transport import TypedPublisher, open_session, subscribe

PREDICTION_ALL = f"{Keys().prefix}/prediction/*"
"""The posterior and the occupancy: the planner consumes the occupancy only."""


def test_denied_names_role_key_and_reason() -> None:
    session, keys = object(), Keys()
    assert denied(session, keys.pose, "put") == ""  # not a secure session
    remember(session, "planner", keys)
    try:
        assert denied(session, keys.plan, "put") == ""
        assert denied(session, keys.pose, "put") == ("role planner may not put foresight/human/pose (its owners: "
                                                     "replayer, tracker): every peer drops it")
        assert denied(session, keys.robot_state, "subscribe") == "" and denied(session, keys.pose, "subscribe") == ""
        assert "may not subscribe to foresight/prediction/posterior" in denied(session, keys.posterior, "subscribe")
    finally:
        forget(session)
    assert denied(session, keys.pose, "put") == ""


def test_a_wildcard_subscription_that_also_matches_keys_the_role_does_not_consume_is_named() -> None:
    """Zenoh refuses such a subscription whole: the planner's foresight/human/* lost the markers it consumes too (when
    it did not consume poses), and an executor run under another role's certificate its whole log, with no word (a
    security review). The planner consumes the occupancy, not the posterior."""
    session, keys = object(), Keys()
    remember(session, "planner", keys)
    try:
        why = denied(session, PREDICTION_ALL, "subscribe")
        assert why.startswith(f"role planner may not subscribe to {PREDICTION_ALL}: it also matches "
                              f"{keys.posterior}") and "refuses the whole expression" in why
        assert denied(session, keys.human_all, "subscribe") == ""  # poses (real time's body term) and markers
        assert "foresight/**" in denied(session, f"{keys.prefix}/**", "subscribe")
    finally:
        forget(session)
    for role in ("executor", "observer"):  # the executor's log and an observer's: allowed whole
        remember(session, role, keys)
        try:
            assert denied(session, f"{keys.prefix}/**", "subscribe") == ""
        finally:
            forget(session)
    remember(session, "predictor", keys)  # its ordered subscription to poses and markers: allowed
    try:
        assert denied(session, keys.human_all, "subscribe") == ""
        # allowed only where an allowed expression includes it whole (Zenoh's rule), not where it meets no other key
        assert "within none of the expressions" in denied(session, f"{keys.prefix}/human/**", "subscribe")
        assert denied(session, "0/some_ros2_topic/**", "subscribe") == ""  # outside the contract: not judged
    finally:
        forget(session)
    remember(session, "executor", keys)
    try:
        assert "may not subscribe to **" in denied(session, "**", "subscribe")
    finally:
        forget(session)


def test_endpoints_and_the_plain_tcp_warning() -> None:
    assert secure_endpoints(["tcp/127.0.0.1:7447", "tls/h:1"]) == ["tls/127.0.0.1:7447", "tls/h:1"]
    with pytest.raises(ConfigError, match="with security every link is TLS .* udp/h:2, ws/h:3 would not be"):
        secure_endpoints(["tcp/127.0.0.1:7447", "udp/h:2", "ws/h:3"])  # plain text beside the TLS links
    assert insecure_listen_warning(["tcp/127.0.0.1:0", "tcp/localhost:7447", "tcp/[::1]:7447"]) == ""
    text = insecure_listen_warning(["tcp/0.0.0.0:7447", "tcp/127.0.0.1:0"])
    assert text.startswith("listening on tcp/0.0.0.0:7447 without security") and "--security DIR" in text


def test_a_secure_service_logs_what_it_may_not_do(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    init_security_dir(tmp_path, ROLES)
    cfg = ZenohConfig(mode="peer", listen=[f"tcp/127.0.0.1:{free_port()}"], connect=[], security_dir=str(tmp_path),
                      role="planner")
    keys = Keys()
    with caplog.at_level(logging.WARNING, logger="shared.transport"), open_session(cfg) as session:
        TypedPublisher(session, keys.plan)
        TypedPublisher(session, keys.pose)
        sub = subscribe(session, keys.robot_state, RobotState, lambda m: None)
        sub2 = subscribe(session, keys.posterior, ClassPosterior, lambda m: None)
        sub.undeclare()
        sub2.undeclare()
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("access control:")]
    assert lines == ["access control: role planner may not put foresight/human/pose (its owners: replayer, "
                     "tracker): every peer drops it", "access control: role planner may not subscribe to "
                     "foresight/prediction/posterior: it will receive nothing"]


def test_a_presence_token_the_role_may_not_declare_is_said(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """`foresight planner --role replayer` logged its denied plan and subscriptions, not its planner token, which
    the router drops: an executor waiting for the planner got no hint (a security review)."""
    from shared.presence import Presence

    init_security_dir(tmp_path, ROLES)
    keys = Keys()
    for role, service in (("replayer", "planner"), ("observer", "observer"), ("planner", "planner")):
        cfg = ZenohConfig(mode="peer", listen=[f"tcp/127.0.0.1:{free_port()}"], connect=[],
                          security_dir=str(tmp_path), role=role)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="shared.transport"), open_session(cfg) as session:
            Presence(session, keys, service).close()
        said = [r.getMessage() for r in caplog.records if "presence token" in r.getMessage()]
        allowed = {"replayer": "foresight/alive/replayer", "observer": "none"}.get(role)
        assert said == ([] if allowed is None else [
            f"access control: role {role} may not declare the presence token foresight/alive/{service} (it may "
            f"declare {allowed}): every peer drops it, and one waiting for it never sees it"])


def test_a_secure_session_says_its_refused_wildcard_subscription(tmp_path: Path,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    """A real planner-role session subscribing in order to foresight/prediction/* (the posterior is not its): Zenoh
    refuses it whole, and it says so."""
    from shared.protocol import OccupancyGrid
    from shared.transport import subscribe_ordered

    init_security_dir(tmp_path, ROLES)
    cfg = ZenohConfig(mode="peer", listen=[f"tcp/127.0.0.1:{free_port()}"], connect=[], security_dir=str(tmp_path),
                      role="planner")
    keys = Keys()
    with caplog.at_level(logging.WARNING, logger="shared.transport"), open_session(cfg) as session:
        sub = subscribe_ordered(session, PREDICTION_ALL, {keys.posterior: ClassPosterior,
                                                         keys.occupancy: OccupancyGrid}, lambda m: None)
        sub.undeclare()
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("access control:")]
    assert any(f"may not subscribe to {PREDICTION_ALL}: it also matches {keys.posterior}" in line
               for line in lines), lines
