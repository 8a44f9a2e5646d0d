"""The ROS 2 domain a command joins: the shell's ``ROS_DOMAIN_ID``, as ROS 2's own tools read it, unless an option says.

Pure: no Zenoh, no ROS. An option table's default must never fail (``--help`` would), so an unreadable variable
becomes :data:`UNREADABLE_DOMAIN`, which :func:`check_domain_id` refuses, naming the variable, in the validation
of a command that joins the domain.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping

from shared.config import ConfigError

__all__ = ["ros_domain_id", "check_domain_id", "UNREADABLE_DOMAIN", "DOMAIN_ID_MAX"]

DOMAIN_ID_MAX = 2 ** 32 - 1
"""The largest domain id taken. rmw_zenoh takes any (a ``size_t`` in its key expressions; rmw_zenoh_cpp
``rmw_init.cpp``), where ROS 2 over DDS takes 0..232 (its UDP ports); a 32-bit bound keeps a typo's 20 digits out."""

_C_UNSIGNED = re.compile(r"(?P<hex>0[xX][0-9a-fA-F]+)|0[0-7]*|[1-9][0-9]*", re.ASCII)
"""A number as C's ``strtoul`` reads it with base 0 (rcl's ``rcl_get_default_domain_id``), all of it."""

UNREADABLE_DOMAIN = -1
"""The default domain id when ``ROS_DOMAIN_ID`` holds no domain id: :func:`check_domain_id` names the variable."""


def ros_domain_id(env: Mapping[str, str] | None = None) -> int:
    """The ROS 2 domain of this shell: ``ROS_DOMAIN_ID`` as ROS 2's own tools read it (0 when unset or empty).

    A shell set up for ROS 2 runs Foresight's nodes on the domain its ``ros2`` commands use; a
    ``FORESIGHT_*_DOMAIN_ID`` variable, the config file or ``--domain-id`` still take precedence. rcl reads the
    variable as C's ``strtoul(s, &end, 0)``: ``010`` is domain 8 (octal), ``0x10`` 16, ``10`` 10; read as decimal,
    ``010`` put Foresight on domain 10 and the nodes of domain 8 never saw it. A value that is not wholly such a
    number (or is negative, or past :data:`DOMAIN_ID_MAX`) gives :data:`UNREADABLE_DOMAIN` -- stricter than rcl,
    which takes the number ``5abc`` or ``+5`` starts with (domain 5), refusing only a 0 with text after it -- refused by
    :func:`check_domain_id` where a command speaks ROS 2 and no option overrides it; an option table's default must
    not fail (``--help`` would).
    """
    raw = (os.environ if env is None else env).get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    match = _C_UNSIGNED.fullmatch(raw)
    if match is None:
        return UNREADABLE_DOMAIN
    value = int(raw, 16) if match["hex"] else int(raw, 8) if raw.startswith("0") else int(raw)
    return value if value <= DOMAIN_ID_MAX else UNREADABLE_DOMAIN


def check_domain_id(value: int, option: str, flag: str) -> None:
    """Refuse a domain id that is not one, naming ``ROS_DOMAIN_ID`` when the value is its unreadable default.

    Args:
        value: The domain id configured.
        option: Its config name (``ros2.domain_id``).
        flag: The flag that overrides it (``--domain-id``).

    Raises:
        ConfigError: The value is no domain id.
    """
    if 0 <= value <= DOMAIN_ID_MAX:
        return
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if value == UNREADABLE_DOMAIN and raw and ros_domain_id() == UNREADABLE_DOMAIN:
        raise ConfigError(f"ROS_DOMAIN_ID={raw!r}: not a ROS 2 domain id (a whole number 0..{DOMAIN_ID_MAX}: decimal, "
                          f"0x hexadecimal or 0 octal, as ROS 2 reads it, and nothing after it), and {option} "
                          f"takes it; set it right, unset it, or give {flag} N")
    raise ConfigError(f"{option}: must be 0..{DOMAIN_ID_MAX}, got {value}")
