"""``foresight router``: a Zenoh session in router mode, the local stand-in for ``zenohd``."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import threading

from shared.config import ZenohConfig, add_config_arguments, resolve_config
from shared.runtime import cli_errors, setup_logging, stop_on_signals
from shared.transport import describe, open_session

__all__ = ["RouterConfig", "main", "ROUTER_ENDPOINT"]

ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"
log = logging.getLogger("foresight.router")


@dataclasses.dataclass
class RouterConfig:
    """Router options (the endpoints are in the [zenoh] section)."""

    log_level: str = dataclasses.field(default="INFO", metadata={"help": "log level",
                                                                 "choices": ("DEBUG", "INFO", "WARNING")})


def main(argv: list[str] | None = None, prog: str = "foresight router") -> int:
    """Run a router until SIGINT/SIGTERM. Listens on tcp/127.0.0.1:7447 unless --listen says otherwise."""
    parser = argparse.ArgumentParser(prog=prog, description=main.__doc__)
    add_config_arguments(parser, "router", RouterConfig)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        base = ZenohConfig(mode="router", listen=[ROUTER_ENDPOINT], connect=[])
        cfg, zcfg = resolve_config("router", RouterConfig, args, zenoh_base=base)
    setup_logging(cfg.log_level)
    stop = threading.Event()
    restore = stop_on_signals(stop)
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
