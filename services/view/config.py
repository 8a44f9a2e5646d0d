"""``foresight view``'s options (a module of its own: the config checks import it without the SDK or torch)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from shared.config import LOG_LEVELS, ConfigError, opt
from shared.devices import check_device
from shared.scene import SCENE_HELP

__all__ = ["ViewConfig", "DEFAULT_PORT", "STATIC_PERIOD_RANGE"]

DEFAULT_PORT = 8765
"""The Foxglove app's default WebSocket port (its "Open connection" dialog proposes ws://localhost:8765)."""

STATIC_PERIOD_RANGE = (0.05, 3600.0)
"""``static_period_s``'s range (s): infinity killed the thread that re-sends the table and cups, a tiny period
would re-send them in a busy loop."""


@dataclass
class ViewConfig:
    """Options of ``foresight view``."""

    port: int = opt(DEFAULT_PORT, help="WebSocket port the Foxglove app connects to (0: any free one)")
    host: str = opt("127.0.0.1", help="address to serve on (loopback: only this machine can watch; the server "
                    "has no access control of its own)")
    scene: str = opt("", help=SCENE_HELP + " (the static scene and the human's placement; empty: pr2_two_cups)")
    viz_rate_hz: float = opt(10.0, help="highest rate of the robot, human and occupancy updates per topic")
    static_period_s: float = opt(1.0, help="the table and cups are sent again this often, for clients that join")
    device: str = opt("cpu", help="torch device of the robot model (cpu or cuda)")
    nice: int = opt(10, help="`foresight view` lowers its CPU priority by this much (0-19): drawing must not "
                    "take CPU from the planning loop on a shared machine")
    write_layout: str = opt("", help="write the Foxglove layout for this scene and --library (3D panel, posterior "
                            "and cost plots) to this file and exit")
    library: str = opt("", help="the motion library whose classes the layout's posterior plot shows (--write-layout):"
                       " a directory of compound_*.csv or a .npz, the one the model was trained on; empty: the "
                       "embedded synthetic library's 8 classes")
    voxel_size: float = opt(0.0, help="the layout's cube per occupancy voxel (m; --write-layout): 0, the scene "
                            "grid's resolution; give the model's when it was trained with another (foresight train "
                            "--resolution), or its voxels are drawn overlapping or apart")
    log_level: str = opt("INFO", help="log level", choices=LOG_LEVELS)

    def validate(self) -> None:
        """Check ranges; raises ConfigError naming the option."""
        if not 0 <= self.port <= 65535:
            raise ConfigError(f"view.port: must be 0..65535, got {self.port}")
        if not (self.viz_rate_hz > 0 and math.isfinite(self.viz_rate_hz)):
            raise ConfigError(f"view.viz_rate_hz: must be a finite number > 0, got {self.viz_rate_hz}")
        lo, hi = STATIC_PERIOD_RANGE
        if not lo <= self.static_period_s <= hi:
            raise ConfigError(f"view.static_period_s: must be {lo:g}..{hi:g} s, got {self.static_period_s}")
        if not (0 <= self.voxel_size <= 1 and math.isfinite(self.voxel_size)):
            raise ConfigError(f"view.voxel_size: must be 0 (the scene's resolution) or a size up to 1 m, got "
                              f"{self.voxel_size}")
        if not 0 <= self.nice <= 19:
            raise ConfigError(f"view.nice: must be 0..19, got {self.nice}")
        check_device(self.device, "view.device")
