"""RobotSimConfig: a bad controller name or joint-state topic is named after the option given (the executor's the same
check under its own names)."""

from __future__ import annotations

import pytest

from services.executor.config import ExecutorConfig
from services.ros2.robot_sim import RobotSimConfig
from shared.config import ConfigError


def test_bad_robot_names_are_named_after_the_option_given() -> None:
    for bad in ("a/b", "r-arm", "1arm", "", "ärm"):  # ROS 2's rule for a name (r-arm and 1arm passed before)
        with pytest.raises(ConfigError, match=rf"^simrobot.controller: a controller name .*got '{bad}'"):
            RobotSimConfig(controller=bad).validate()
    with pytest.raises(ConfigError, match=r"^simrobot.joint_states: an absolute topic"):
        RobotSimConfig(joint_states="joint_states").validate()
    with pytest.raises(ConfigError, match=r"^executor.ros2_controller: a controller name"):
        ExecutorConfig(ros2_controller="").validate()
    with pytest.raises(ConfigError, match=r"^executor.ros2_joint_states: each part .* 'joint_\*' of '/joint_\*'"):
        ExecutorConfig(ros2_joint_states="/joint_*").validate()
    RobotSimConfig(controller="r_arm_controller_2").validate()


def test_a_misspelt_stop_with_service_is_named_with_the_closest() -> None:
    """Misspelt, the service was never seen going, and the robot or the gateway ran on without a word."""
    from services.ros2.service import Ros2ServiceConfig

    for make, option in ((lambda s: RobotSimConfig(stop_with=s), "simrobot.stop_with"),
                         (lambda s: Ros2ServiceConfig(stop_with=s), "ros2.stop_with")):
        with pytest.raises(ConfigError, match=rf"^{option}: unknown service 'exectuor' \(did you mean 'executor'\?\)"):
            make(["planner", "exectuor"]).validate()
        make(["executor"]).validate()
        make([]).validate()


@pytest.mark.parametrize("section", ["simrobot", "ros2"])
def test_stop_with_is_a_list_of_services_as_everywhere_else(section: str) -> None:
    """It was one name in [ros2] and [simrobot]: ``--stop-with executor,planner`` was an unknown service there and a
    list in the other services; a single name still reads as a list of one."""
    import argparse

    from services.ros2.service import Ros2ServiceConfig
    from shared.config import add_config_arguments, resolve_config

    cls = RobotSimConfig if section == "simrobot" else Ros2ServiceConfig
    parser = argparse.ArgumentParser()
    add_config_arguments(parser, section, cls)
    for argv, env, expected in ((["--stop-with", "executor,planner"], {}, ["executor", "planner"]),
                                ([], {f"FORESIGHT_{section.upper()}_STOP_WITH": "executor"}, ["executor"]),
                                ([], {}, [])):
        cfg = resolve_config(section, cls, parser.parse_args(argv), env=env)[0]
        assert cfg.stop_with == expected
