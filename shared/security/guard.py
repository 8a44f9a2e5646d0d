"""What the access control will refuse a session, said by the session itself when it declares it.

Zenoh drops a denied put or subscription silently on the receiving side. A Foresight session knows
its role and the generated rules (:mod:`shared.security.acl`), so :class:`shared.transport.TypedPublisher`,
:func:`shared.transport.subscribe` and :class:`shared.presence.Presence` (its token) log one line naming the role,
the key and the reason when they declare something the rules deny, and the service keeps running.
"""

from __future__ import annotations

from typing import Any

from shared.protocol import Keys

from .acl import consumed_keys, owned_keys, subscription_exprs, token_keys

__all__ = ["remember", "forget", "denied"]

_ROLES: dict[int, tuple[str, Keys]] = {}  # id(session) -> (role, keys) of the open secure sessions


def remember(session: Any, role: str, keys: Keys) -> None:
    """Note that ``session`` presents ``role``'s certificate (called by :func:`shared.transport.open_session`)."""
    _ROLES[id(session)] = (role, keys)


def forget(session: Any) -> None:
    """The session is closing."""
    _ROLES.pop(id(session), None)


def denied(session: Any, key: str, kind: str) -> str:
    """Why the access control drops ``kind`` (``put``, ``subscribe`` or ``token``) on ``key`` from ``session``.

    "" if it does not. Only sessions opened with security are known here; others get "".
    """
    entry = _ROLES.get(id(session))
    if entry is None:
        return ""
    role, keys = entry
    if kind == "token":
        allowed = token_keys(keys, role)
        if keys.alive_all in allowed or key in allowed:
            return ""
        return (f"role {role} may not declare the presence token {key} (it may declare "
                f"{', '.join(allowed) or 'none'}): every peer drops it, and one waiting for it never sees it")
    routes = keys.routes()
    if kind == "subscribe" and key not in routes and any(c in key for c in "*$"):
        return _wildcard_denied(keys, role, key)
    if key not in routes:
        return ""
    if kind == "put" and key not in owned_keys(keys, role):
        return f"role {role} may not put {key} (its owners: {', '.join(routes[key][0])}): every peer drops it"
    if kind == "subscribe" and key not in consumed_keys(keys, role):
        return f"role {role} may not subscribe to {key}: it will receive nothing"
    return ""


def _wildcard_denied(keys: Keys, role: str, expr: str) -> str:
    """Why a subscription to the wildcard ``expr`` is refused ("" if it is not).

    Zenoh allows a subscription only where an allowed key expression includes it whole; one that also matches a
    key the role does not consume is refused, so the keys it does consume are lost with it (a planner's
    ``foresight/prediction/*``: it consumes the occupancy, not the posterior; an executor run under another role's
    certificate: its log's ``foresight/**``). An
    expression that meets no key of the contract (a ROS 2 node's keys) is not judged here.
    """
    import zenoh

    wanted = zenoh.KeyExpr(expr)
    if not any(wanted.intersects(zenoh.KeyExpr(k)) for k in keys.routes()):
        return ""
    allowed = subscription_exprs(keys, role)
    if any(zenoh.KeyExpr(a).includes(wanted) for a in allowed):
        return ""
    consumed = set(consumed_keys(keys, role))
    lost = [k for k in keys.routes() if k not in consumed and wanted.intersects(zenoh.KeyExpr(k))]
    why = (f"it also matches {', '.join(lost[:3])}{' ...' if len(lost) > 3 else ''}, which the role does not consume"
           if lost else f"it is within none of the expressions the role may subscribe to "
           f"({', '.join(a for a in allowed if '*' in a) or 'only its keys, one by one'})")
    return (f"role {role} may not subscribe to {expr}: {why}, so the access control refuses the whole expression "
            "and it will receive nothing")
