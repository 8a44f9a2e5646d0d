"""RobotSimConfig: a bad controller name or joint-state topic is named after the option given (the executor's the same
check under its own names)."""

from __future__ import annotations

import pytest

from services.executor.config import ExecutorConfig
from services.ros2.robot_sim import RobotSimConfig
from shared.config import ConfigError


def test_bad_robot_names_are_named_after_the_option_given() -> None:
    with pytest.raises(ConfigError, match=r"^simrobot.controller: a controller name \(no '/'\), got 'a/b'"):
        RobotSimConfig(controller="a/b").validate()
    with pytest.raises(ConfigError, match=r"^simrobot.joint_states: an absolute topic"):
        RobotSimConfig(joint_states="joint_states").validate()
    with pytest.raises(ConfigError, match=r"^executor.ros2_controller: a controller name"):
        ExecutorConfig(ros2_controller="").validate()
    with pytest.raises(ConfigError, match=r"^executor.ros2_joint_states: an absolute topic"):
        ExecutorConfig(ros2_joint_states="/joint_*").validate()
