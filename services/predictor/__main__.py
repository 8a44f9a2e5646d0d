"""``python -m services.predictor`` / ``foresight predictor``: early prediction of the human's workspace occupancy."""

from __future__ import annotations

import argparse
import sys
import threading

from shared.config import add_config_arguments, resolve_config
from shared.runtime import UserError, cli_errors, setup_logging, stop_on_signals

from .core import PredictorConfig
from .service import PredictorService

__all__ = ["main"]

DESCRIPTION = """Subscribe to HumanPose and DemoMarker; for every pose publish the class posterior
(ClassPosterior) and the workspace occupancy (OccupancyGrid): the predicted p(x|xi) of the paper or,
with --method current, the current posture's voxels only. Resets on each demonstration start marker.
Needs a model file from `foresight train`. Options come from the dataclass defaults < --config FILE
([predictor], [zenoh]) < env FORESIGHT_PREDICTOR_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def main(argv: list[str] | None = None, prog: str = "python -m services.predictor") -> int:
    """Run the predictor service; returns the exit status (0 stopped, 2 bad input)."""
    parser = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    add_config_arguments(parser, "predictor", PredictorConfig)
    args = parser.parse_args(argv)
    with cli_errors(prog):
        cfg, zcfg = resolve_config("predictor", PredictorConfig, args)
        setup_logging(cfg.log_level)
        if not cfg.model.is_file():
            raise UserError(f"model file {str(cfg.model)!r} not found; run `foresight train --out {cfg.model}` first")
        service = PredictorService(cfg, zcfg)
        stop = threading.Event()
        restore = stop_on_signals(stop)
        try:
            service.run(stop)
        finally:
            restore()
    return 0


if __name__ == "__main__":
    sys.exit(main())
