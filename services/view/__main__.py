"""``python -m services.view`` / ``foresight view``: a running system served live to the Foxglove app."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable

from shared.config import ZenohConfig
from shared.native_threads import limit_torch_threads
from shared.runtime import lower_priority, service_main

from .service import ViewConfig, ViewService

__all__ = ["main"]

DESCRIPTION = """Serve a running Foresight system live to the Foxglove app: the robot, the person, the
predicted occupancy (coloured by probability), the candidate paths (the chosen one green), the class
posterior and the costs, on ws://127.0.0.1:8765 (Foxglove: Open connection -> Foxglove WebSocket; open
the layout docs/foresight.foxglove.json). It subscribes as the read-only observer when security is on.
(`foresight demo --live` serves the same scene from its executor, at the executor's viz_rate_hz, not
from this command.) docs/live-view.md has the walk-through.
Options: defaults < --config FILE ([view], [zenoh]) < env FORESIGHT_VIEW_<NAME> / FORESIGHT_ZENOH_<NAME> < flags."""


def _make(cfg: ViewConfig, zcfg: ZenohConfig, stop: threading.Event) -> Callable[[], object]:
    if cfg.write_layout:
        return lambda: _write_layout(cfg)
    limit_torch_threads(1)  # its torch work is the robot's forward kinematics: a second thread only spins
    service = ViewService(cfg, zcfg)
    lower_priority(cfg.nice)
    return lambda: service.run(stop)


def _write_layout(cfg: ViewConfig) -> None:
    from pathlib import Path

    from shared.foxglove.layout import foresight_layout, layout_text, library_class_names
    from shared.scene import load_scene

    path = Path(cfg.write_layout)
    classes = library_class_names(cfg.library)  # the posterior's classes are the library's, not the scene's cups
    path.write_text(layout_text(foresight_layout(load_scene(cfg.scene or None), class_names=classes,
                                                 voxel_size=cfg.voxel_size or None)))
    print(f"foresight view: wrote the Foxglove layout {path} (Foxglove: Layouts -> Import from file)")


def main(argv: list[str] | None = None, prog: str = "python -m services.view") -> int:
    """Run the live view; returns the exit status (0 stopped, 2 bad input)."""
    return service_main(argv, prog, section="view", config_cls=ViewConfig, description=DESCRIPTION, make=_make)


if __name__ == "__main__":
    sys.exit(main())
