"""The ROS 2 domain a command joins: the shell's ``ROS_DOMAIN_ID``, as ROS 2's own tools read it, unless an option says.

Pure: no Zenoh, no ROS. An option table's default must never fail (``--help`` would), so an unreadable variable
becomes :data:`UNREADABLE_DOMAIN`, which :func:`check_domain_id` refuses, naming the variable, in the validation
of a command that joins the domain.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

from shared.config import ConfigError

__all__ = ["ros_domain_id", "check_domain_id", "UNREADABLE_DOMAIN"]

UNREADABLE_DOMAIN = -1
"""The default domain id when ``ROS_DOMAIN_ID`` holds no domain id: :func:`check_domain_id` names the variable."""


def ros_domain_id(env: Mapping[str, str] | None = None) -> int:
    """The ROS 2 domain of this shell: ``ROS_DOMAIN_ID`` as ROS 2's own tools read it (0 when unset or empty).

    A shell set up for ROS 2 runs Foresight's nodes on the domain its ``ros2`` commands use; a
    ``FORESIGHT_*_DOMAIN_ID`` variable, the config file or ``--domain-id`` still take precedence. A value that is not
    a domain id (0..232) gives :data:`UNREADABLE_DOMAIN`, refused by :func:`check_domain_id` where a command speaks
    ROS 2 and no option overrides it; an option table's default must not fail (``--help`` would).
    """
    raw = (os.environ if env is None else env).get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    if not raw.isdigit() or not raw.isascii() or int(raw) > 232:
        return UNREADABLE_DOMAIN
    return int(raw)


def check_domain_id(value: int, option: str, flag: str) -> None:
    """Refuse a domain id outside 0..232, naming ``ROS_DOMAIN_ID`` when the value is its unreadable default.

    Args:
        value: The domain id configured.
        option: Its config name (``ros2.domain_id``).
        flag: The flag that overrides it (``--domain-id``).

    Raises:
        ConfigError: The value is no domain id.
    """
    if 0 <= value <= 232:
        return
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if value == UNREADABLE_DOMAIN and raw and ros_domain_id() == UNREADABLE_DOMAIN:
        raise ConfigError(f"ROS_DOMAIN_ID={raw!r}: not a ROS 2 domain id (0..232), and {option} takes it; set it "
                          f"right, unset it, or give {flag} N")
    raise ConfigError(f"{option}: must be 0..232, got {value}")
