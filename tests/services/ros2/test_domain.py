"""The ROS 2 domain a command joins: the shell's ROS_DOMAIN_ID unless an option says; refused only where used."""

from __future__ import annotations

import pytest


def test_the_shells_ros_domain_id_is_the_default_domain(monkeypatch) -> None:
    """A shell set up for ROS 2 ran Foresight's nodes on domain 0 whatever its ROS_DOMAIN_ID said."""
    from services.ros2.core import Ros2Config
    from services.ros2.domain import UNREADABLE_DOMAIN, ros_domain_id
    from services.ros2.robot_sim import RobotSimConfig
    from services.tracker.config import TrackerServiceConfig

    assert ros_domain_id({}) == 0 and ros_domain_id({"ROS_DOMAIN_ID": " "}) == 0
    assert ros_domain_id({"ROS_DOMAIN_ID": "42"}) == 42
    # as rcl reads it (C's strtoul, base 0): read as decimal, 010 put Foresight on domain 10 and ROS 2 on 8
    for raw, domain in (("010", 8), ("0x10", 16), ("0X1f", 31), ("0", 0), ("00", 0), ("250", 250)):
        assert ros_domain_id({"ROS_DOMAIN_ID": raw}) == domain, raw  # 250: rmw_zenoh takes it (DDS would not)
    for bad in ("-1", "x", "٣", "5abc", "09", "0x", "+5", "4294967296"):
        assert ros_domain_id({"ROS_DOMAIN_ID": bad}) == UNREADABLE_DOMAIN, bad  # refused where used, not a default
    monkeypatch.setenv("ROS_DOMAIN_ID", "5")
    assert Ros2Config().domain_id == RobotSimConfig().domain_id == TrackerServiceConfig().ros2_domain_id == 5
    from services.executor.config import ExecutorConfig  # the executor stayed on 0 and never heard the robot

    assert ExecutorConfig().ros2_domain_id == 5
    assert Ros2Config(domain_id=7).domain_id == 7  # a flag, variable or file still decides


def test_an_unreadable_ros_domain_id_is_refused_only_where_ros2_is_spoken(monkeypatch, capsys) -> None:
    """Before, building any option table with ROS 2 options raised: every command, --help included, ended in a
    traceback, and --domain-id did not help."""
    from services.executor.config import ExecutorConfig
    from services.ros2.core import Ros2Config
    from services.ros2.robot_sim import RobotSimConfig
    from services.tracker.config import TrackerServiceConfig
    from shared.config import ConfigError
    from tools.foresight import main

    monkeypatch.setenv("ROS_DOMAIN_ID", "abc")
    for make, option, flag in ((Ros2Config, "ros2.domain_id", "--domain-id"),
                               (RobotSimConfig, "simrobot.domain_id", "--domain-id"),
                               (lambda: ExecutorConfig(robot="ros2"), "executor.ros2_domain_id", "--ros2-domain-id"),
                               (lambda: TrackerServiceConfig(input="ros2"), "tracker.ros2_domain_id",
                                "--ros2-domain-id")):
        with pytest.raises(ConfigError, match=f"ROS_DOMAIN_ID='abc'.*{option}.*{flag} N"):
            make().validate()
    Ros2Config(domain_id=3).validate()  # an option overrides it
    ExecutorConfig().validate()  # the simulated arm speaks no ROS 2
    TrackerServiceConfig().validate()  # keypoints over Zenoh
    Ros2Config(domain_id=300).validate()  # rmw_zenoh takes any domain id (DDS only 0..232)
    with pytest.raises(ConfigError, match=r"^ros2.domain_id: must be 0..4294967295, got -2$"):
        Ros2Config(domain_id=-2).validate()
    with pytest.raises(ConfigError, match=r"^simrobot.node: a name of letters"):  # its own option, not the gateway's
        RobotSimConfig(domain_id=0, node="pr2-sim").validate()
    for command in ("ros2", "executor", "tracker", "simrobot"):
        with pytest.raises(SystemExit) as exit_:
            main([command, "--help"])
        assert exit_.value.code == 0 and "usage" in capsys.readouterr().out
