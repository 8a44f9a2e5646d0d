"""``foresight router``: a Zenoh session in router mode, the local stand-in for ``zenohd``."""

from __future__ import annotations

import dataclasses
import logging
import re
import threading

from shared.arguments import ArgumentParser
from shared.config import ConfigError, ZenohConfig, add_config_arguments, resolve_config
from shared.runtime import cli_errors, setup_logging, stop_on_signals, watch_parent
from shared.transport import describe, open_session

__all__ = ["RouterConfig", "main", "check_listen", "ROUTER_ENDPOINT"]

ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"
log = logging.getLogger("foresight.router")


@dataclasses.dataclass
class RouterConfig:
    """Router options (the endpoints are in the [zenoh] section)."""

    log_level: str = dataclasses.field(default="INFO", metadata={"help": "log level",
                                                                 "choices": ("DEBUG", "INFO", "WARNING")})


def check_listen(listen: list[str]) -> None:
    """A router must listen on a port its peers can be told.

    Raises:
        ConfigError: ``listen`` is empty (the router would be reachable by no one) or names port 0 (a port
            picked at start that no peer can know, and Zenoh cannot report).
    """
    if not listen:
        raise ConfigError(f"zenoh.listen: empty; a router must listen on an endpoint, e.g. {ROUTER_ENDPOINT}")
    for ep in listen:
        port = re.split(r"[/#?]", ep.split("/", 1)[1].rsplit(":", 1)[-1])[0]  # tcp/HOST:PORT[#...]
        if port.isdigit() and int(port) == 0:
            raise ConfigError(f"zenoh.listen: {ep!r} asks for a free port, which the services could not be told; "
                              f"give the port they connect to, e.g. {ROUTER_ENDPOINT}")


def main(argv: list[str] | None = None, prog: str = "foresight router") -> int:
    """Run a router until SIGINT/SIGTERM. Listens on tcp/127.0.0.1:7447 unless --listen says otherwise."""
    parser = ArgumentParser(prog=prog, description=main.__doc__)
    base = ZenohConfig(mode="router", listen=[ROUTER_ENDPOINT], connect=[])
    add_config_arguments(parser, "router", RouterConfig, zenoh_base=base)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, zcfg = resolve_config("router", RouterConfig, args, zenoh_base=base)
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
