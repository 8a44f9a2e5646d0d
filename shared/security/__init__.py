"""Mutual TLS and access control for Foresight's Zenoh sessions (docs/security.md).

:mod:`~shared.security.certificates` makes the authority and one certificate per role;
:mod:`~shared.security.acl` generates Zenoh's access control from the wire contract;
:mod:`~shared.security.tls` turns a security directory and a role into a session's TLS settings.
"""

from .acl import OBSERVER, ROLES, ROUTER, access_control
from .tls import insecure_listen_warning, secure_endpoints, tls_settings

__all__ = ["ROLES", "ROUTER", "OBSERVER", "access_control", "tls_settings", "secure_endpoints",
           "insecure_listen_warning"]
