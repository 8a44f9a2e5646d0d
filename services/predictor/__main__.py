"""``python -m services.predictor`` / ``foresight predictor``: early prediction of the human's workspace occupancy."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.data_files import relative_to_cwd
from shared.runtime import UserError, service_main

from .core import PredictorConfig
from .service import PredictorService

__all__ = ["main"]

DESCRIPTION = """Subscribe to HumanPose and DemoMarker; for every pose publish the class posterior
(ClassPosterior) and the workspace occupancy (OccupancyGrid): the predicted p(x|xi) of the paper or,
with --method current, the current posture's voxels only. Resets on each demonstration start marker.
Needs a model file from `foresight train`. Options come from the dataclass defaults < --config FILE
([predictor], [zenoh]) < env FORESIGHT_PREDICTOR_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def _make(cfg: PredictorConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    if not cfg.model.exists():
        raise UserError(f"model file {str(cfg.model)!r} not found{relative_to_cwd(cfg.model)}; run `foresight train "
                        f"--out {cfg.model}` first")
    service = PredictorService(cfg, zcfg)  # a directory or an unreadable file: the model's own error names it
    return lambda: service.run(stop)


def main(argv: list[str] | None = None, prog: str = "python -m services.predictor") -> int:
    """Run the predictor service; returns the exit status (0 stopped, 2 bad input)."""
    return service_main(argv, prog, section="predictor", config_cls=PredictorConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
