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
    for bad in ("-1", "233", "x", "٣"):
        assert ros_domain_id({"ROS_DOMAIN_ID": bad}) == UNREADABLE_DOMAIN  # refused where used, not in a default
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
                               (RobotSimConfig, "ros2.domain_id", "--domain-id"),
                               (lambda: ExecutorConfig(robot="ros2"), "executor.ros2_domain_id", "--ros2-domain-id"),
                               (lambda: TrackerServiceConfig(input="ros2"), "tracker.ros2_domain_id",
                                "--ros2-domain-id")):
        with pytest.raises(ConfigError, match=f"ROS_DOMAIN_ID='abc'.*{option}.*{flag} N"):
            make().validate()
    Ros2Config(domain_id=3).validate()  # an option overrides it
    ExecutorConfig().validate()  # the simulated arm speaks no ROS 2
    TrackerServiceConfig().validate()  # keypoints over Zenoh
    with pytest.raises(ConfigError, match=r"ros2.domain_id: must be 0..232, got 300"):
        Ros2Config(domain_id=300).validate()
    for command in ("ros2", "executor", "tracker", "simrobot"):
        with pytest.raises(SystemExit) as exit_:
            main([command, "--help"])
        assert exit_.value.code == 0 and "usage" in capsys.readouterr().out
