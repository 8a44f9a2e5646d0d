"""``foresight router``: a Zenoh session in router mode, the local stand-in for ``zenohd``."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import threading

from shared.arguments import ArgumentParser
from shared.config import LOG_LEVELS, ConfigError, ZenohConfig, add_config_arguments, resolve_config
from shared.endpoints import picked_port
from shared.runtime import cli_errors, setup_logging, stop_on_signals, watch_parent
from shared.transport import describe, open_session

__all__ = ["RouterConfig", "main", "check_listen", "check_mode", "ROUTER_ENDPOINT"]

ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"
log = logging.getLogger("foresight.router")


@dataclasses.dataclass
class RouterConfig:
    """Router options (the endpoints are in the [zenoh] section)."""

    log_level: str = dataclasses.field(default="INFO", metadata={"help": "log level", "choices": LOG_LEVELS})


def check_listen(listen: list[str]) -> None:
    """A router must listen on a port its peers can be told.

    Raises:
        ConfigError: ``listen`` is empty (the router would be reachable by no one) or names port 0 (a port
            picked at start that no peer can know, and Zenoh cannot report).
    """
    if not listen:
        raise ConfigError(f"zenoh.listen: empty; a router must listen on an endpoint, e.g. {ROUTER_ENDPOINT}")
    for ep in listen:
        if picked_port(ep):
            raise ConfigError(f"zenoh.listen: {ep!r} asks for a free port, which the services could not be told; "
                              f"give the port they connect to, e.g. {ROUTER_ENDPOINT}")


def check_mode(args: argparse.Namespace) -> None:
    """Refuse ``--zenoh-mode`` naming another mode than ``router``.

    A router always runs in router mode: the ``[zenoh]`` table's ``mode`` and ``FORESIGHT_ZENOH_MODE`` are the
    services' and do not apply to it (``mode = "client"`` made it a client, ``peer`` a peer that logged "router
    listening").

    Raises:
        ConfigError: ``args`` has another ``--zenoh-mode``.
    """
    mode = vars(args).get("zenoh__mode", "router")
    if mode != "router":
        raise ConfigError(f"--zenoh-mode: {mode!r}; a router runs in router mode (leave the flag out)")


def main(argv: list[str] | None = None, prog: str = "foresight router") -> int:
    """Run a router until SIGINT/SIGTERM. Listens on tcp/127.0.0.1:7447 unless --listen says otherwise."""
    parser = ArgumentParser(prog=prog, description=main.__doc__)
    base = ZenohConfig(mode="router", listen=[ROUTER_ENDPOINT], connect=[])
    add_config_arguments(parser, "router", RouterConfig, zenoh_base=base)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        check_mode(args)
        cfg, zcfg = resolve_config("router", RouterConfig, args, zenoh_base=base, zenoh_fixed=("mode",))
        check_listen(zcfg.listen)
    setup_logging(cfg.log_level)
    stop = threading.Event()
    restore = stop_on_signals(stop, prog=prog)
    watch_parent(stop)  # started by foresight demo or a bench: stop when it has gone, as its services do
    try:
        with cli_errors(prog), open_session(zcfg) as session:
            log.info("router listening on %s (%s)", ",".join(zcfg.listen), describe(session)["zid"])
            while not stop.wait(1.0):
                pass
    finally:
        restore()
    log.info("router stopped")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
