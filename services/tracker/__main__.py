"""``python -m services.tracker`` / ``foresight tracker``: a live person's keypoints -> the human's poses."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.runtime import service_main
from shared.security.acl import refuse_ros2_keys

from .config import TrackerServiceConfig
from .service import TrackerService

__all__ = ["main"]

DESCRIPTION = """Take a body tracker's keypoint frames (HumanKeypoints on <prefix>/sensor/keypoints, or a ROS 2
geometry_msgs/PoseArray with --input ros2), fit the human model to each (the paper's 12 posture features),
refuse implausible frames (each counted; at most one line per reason a second), smooth, bridge short gaps,
and publish HumanPose with DemoMarker start/end around each reach, as the replayer does for a recording.
--from FILE (short for --from-file) plays a keypoint recording (<class>.csv of a keypoint library) in real time
instead of a sensor.
docs/keypoints.md. Options come from the dataclass defaults < --config FILE ([tracker], [zenoh]) < env
FORESIGHT_TRACKER_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def _make(cfg: TrackerServiceConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    if cfg.input == "ros2":
        refuse_ros2_keys(zcfg.security_dir, "foresight tracker --input ros2")
    service = TrackerService(cfg, zcfg)
    return lambda: service.run(stop)


def main(argv: list[str] | None = None, prog: str = "python -m services.tracker") -> int:
    """Run the tracker; returns the exit status (0 stopped or played, 2 bad input)."""
    args = sys.argv[1:] if argv is None else argv  # --from, as the docs write it: --from-file's name, not a prefix
    args = ["--from-file" if a == "--from" else "--from-file=" + a[7:] if a.startswith("--from=") else a for a in args]
    return service_main(args, prog, section="tracker", config_cls=TrackerServiceConfig, description=DESCRIPTION,
                        make=_make)


if __name__ == "__main__":
    sys.exit(main())
