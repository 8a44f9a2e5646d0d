"""Zenoh access control generated from the wire contract: a role may write only what it owns.

Subjects are matched by the common name of the certificate a remote session presents (the role:
:mod:`shared.security.certificates`). The rules are derived from :data:`shared.protocol.ROUTES`
(each data key's owners and consumers) and nothing else; every message kind not allowed here
is denied (``default_permission: deny``). Zenoh applies them on every unicast link, in router, peer
and client sessions alike, from the point of view of the session holding the config: *ingress*
rules govern what a remote subject may send to it, *egress* rules what it may send to the subject.

Per data key ``k`` with owners ``O`` and consumers ``C``:

* ``put`` in from ``O`` (and from the router, which forwards it); ``put`` out to ``C``, the observer
  and the router;
* ``declare_subscriber`` in from ``C``, the observer and the router (a subscription tells the
  publisher to send), out to every role (a session announces its own subscriptions to its peers).

Liveliness (``<prefix>/alive/<service>``): each service declares its own token only (the router
forwards all); every role may watch the tokens (``declare_liveliness_subscriber``,
``liveliness_query``, its ``reply``). The sensor and the observer declare no token; the observer puts nothing.

What a router certificate can do follows from forwarding: it may send any key. A stolen role key
acts as that role (docs/security.md). A client session's rules name the router only (:func:`remote_roles`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from shared.config_tree import ConfigError
from shared.protocol import SENSOR, SERVICES, Keys

__all__ = ["ROLES", "ROUTER", "OBSERVER", "access_control", "remote_roles", "owned_keys", "consumed_keys",
           "subscription_exprs", "token_keys"]

ROUTER = "router"
OBSERVER = "observer"
ROLES = (ROUTER, *SERVICES, SENSOR, OBSERVER)
"""Every certificate role: the router, each service (:data:`shared.protocol.SERVICES`), a body tracker's driver
(:data:`shared.protocol.SENSOR`: keypoints only), the read-only observer."""


def token_keys(keys: Keys, role: str) -> list[str]:
    """The presence tokens ``role`` may declare: a service its own, the router every one, the others none."""
    if role == ROUTER:
        return [keys.alive_all]
    return [keys.alive(role)] if role in SERVICES else []


def refuse_ros2_keys(security_dir: str, what: str, option: str = "--security") -> None:
    """Raise a ConfigError when ``what`` (a command that speaks ROS 2 keys) is asked to run under access control.

    The rules cover the wire contract's keys only; every peer would drop a ROS 2 key's messages without a word.
    """
    if security_dir:
        raise ConfigError(f"{what} with {option}: ROS 2 keys have no role in the access control yet (docs/ros2.md); "
                          "run one or the other")


def owned_keys(keys: Keys, role: str) -> list[str]:
    """The data keys ``role`` publishes."""
    return [key for key, (owners, _) in keys.routes().items() if role in owners]


def consumed_keys(keys: Keys, role: str) -> list[str]:
    """The data keys ``role`` may receive (the observer and the router: all)."""
    every = keys.routes()
    if role in (OBSERVER, ROUTER):
        return list(every)
    return [key for key, (_, consumers) in every.items() if role in consumers]


def subscription_exprs(keys: Keys, role: str) -> list[str]:
    """The key expressions ``role`` may subscribe to: its consumed keys and the wildcards that match only those.

    Zenoh checks a subscription's own key expression, so a service subscribing to ``foresight/human/*``
    (the predictor, poses and markers in one ordered stream) or ``foresight/**`` (the executor's log)
    needs that expression allowed; it is, exactly when every data key it matches is one the role consumes.
    """
    consumed = consumed_keys(keys, role)
    every = list(keys.routes())
    wildcards = [f"{keys.prefix}/**", *dict.fromkeys(f"{k.rsplit('/', 1)[0]}/*" for k in every)]

    def matches(pattern: str, key: str) -> bool:
        if pattern.endswith("/**"):
            return key.startswith(pattern[:-2])
        return key.rsplit("/", 1)[0] == pattern[:-2]

    allowed = [w for w in wildcards if all(k in consumed for k in every if matches(w, k))]
    return [*consumed, *allowed]


def _rule(rule_id: str, messages: list[str], flows: list[str], key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "messages": messages, "flows": flows, "key_exprs": key_exprs}


def access_control(keys: Keys, remotes: Sequence[str] = ROLES) -> dict[str, Any]:
    """The ``access_control`` section of a Zenoh config for the keys under ``keys.prefix``.

    Args:
        keys: The wire contract's keys.
        remotes: The roles this session may exchange anything with; a remote presenting another role's
            certificate gets nothing and is heard in nothing (``default_permission``). A client session talks to
            its router only (:func:`remote_roles`): a machine answering at the router's address with another
            role's certificate (every certificate names the same hosts) reads none of its puts.

    Returns:
        A JSON-ready dict: ``enabled``, ``default_permission`` (deny), ``rules``, ``subjects`` (one
        per role, by certificate common name) and ``policies`` (which rules apply to which subject).
    """
    rules: list[dict[str, Any]] = []
    policies: dict[str, list[str]] = {role: [] for role in ROLES}

    def grant(role: str, rule: dict[str, Any]) -> None:
        if not any(r["id"] == rule["id"] for r in rules):
            rules.append(rule)
        policies[role].append(rule["id"])

    for role in ROLES:
        owned = owned_keys(keys, role) if role != ROUTER else list(keys.routes())
        if owned:
            grant(role, _rule(f"{role}: put in", ["put"], ["ingress"], owned))
        consumed = consumed_keys(keys, role)
        if consumed:
            grant(role, _rule(f"{role}: put out", ["put"], ["egress"], consumed))
            grant(role, _rule(f"{role}: subscribe in", ["declare_subscriber"], ["ingress"],
                              subscription_exprs(keys, role)))
        grant(role, _rule("subscribe out", ["declare_subscriber"], ["egress"], [f"{keys.prefix}/**"]))
        watch = ["declare_liveliness_subscriber", "liveliness_query", "reply"]
        grant(role, _rule("watch presence", watch, ["ingress", "egress"], [keys.alive_all]))
        grant(role, _rule("presence out", ["liveliness_token"], ["egress"], [keys.alive_all]))
        tokens = token_keys(keys, role)
        if tokens:
            grant(role, _rule(f"{role}: presence in", ["liveliness_token"], ["ingress"], tokens))
    unknown = [r for r in remotes if r not in ROLES]
    if unknown or not remotes:
        raise ValueError(f"access_control: remotes {list(remotes)} must be roles of {', '.join(ROLES)}")
    used = {rule_id for role in remotes for rule_id in policies[role]}
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [rule for rule in rules if rule["id"] in used],
        "subjects": [{"id": role, "cert_common_names": [role]} for role in ROLES if role in remotes],
        "policies": [{"id": role, "rules": ids, "subjects": [role]} for role, ids in policies.items()
                     if role in remotes],
    }


def remote_roles(mode: str) -> tuple[str, ...]:
    """The roles a session in Zenoh ``mode`` exchanges anything with: a client its router only, else every role."""
    return (ROUTER,) if mode == "client" else ROLES
