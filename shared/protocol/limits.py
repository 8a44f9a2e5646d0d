"""Every bound of the wire contract in one place (documented in docs/protocol.md, "Limits").

Two kinds:

* **Sizes** a message declares (payload bytes, array axes, grid cells, string lengths). The decoder
  checks them before it allocates anything, so no message can make a receiver allocate more than
  about :data:`MAX_PAYLOAD_BYTES` plus one dense grid of at most :data:`MAX_GRID_CELLS` voxels.
* **Values** checked on receipt (:mod:`shared.protocol.validation`): stamps, ticks, periods,
  magnitudes and the tolerances the receiver's own model is checked with (joint limits, velocities).

The limits are generous next to what the system sends (a 64^3 grid, 2 to 8 goals of 32 to 128
waypoints, 8 joints, 8 classes, 12 features); they exist to turn an absurd or hostile declaration
into a one-line rejection instead of an allocation or a crash.
"""

from __future__ import annotations

__all__ = [
    "MAX_PAYLOAD_BYTES", "MAX_STRING_CHARS", "MAX_CLASSES", "MAX_GOALS", "MAX_WAYPOINTS", "MAX_JOINTS",
    "MAX_GRID_DIM", "MAX_GRID_CELLS", "MAX_KEYPOINTS", "AXIS_LIMITS", "MAX_TICK", "MAX_SAMPLES", "MAX_DEMO_ID",
    "MIN_RESOLUTION_M", "MAX_RESOLUTION_M", "MAX_COORDINATE_M", "MAX_KEYPOINT_M", "MAX_FRAME", "MIN_PERIOD_S",
    "MAX_PERIOD_S", "MIN_DT_S",
    "MAX_DT_S", "MAX_PLANNING_MS", "MAX_ABS_COST", "MAX_ABS_JOINT", "MAX_ABS_JOINT_VELOCITY",
    "JOINT_LIMIT_TOL", "VELOCITY_LIMIT_TOL", "STAMP_FUTURE_S", "STAMP_PAST_S", "MAX_LOGICAL_STAMP_S",
    "LOGICAL_STAMP_TOL_S", "CLOCK_STAMP_RTOL",
]

# -- sizes (checked by the decoder before anything is allocated) -----------------------------------

MAX_PAYLOAD_BYTES = 16 * 1024 * 1024
"""Largest payload decoded at all (16 MiB; a full 64^3 grid with every voxel set is 1.3 MB)."""
MAX_STRING_CHARS = 256
"""Longest string field, and longest entry of a string list (names, reasons)."""
MAX_CLASSES = 256
"""Axis ``M``: motion classes of a posterior."""
MAX_GOALS = 64
"""Axis ``K``: goals (candidate trajectories) of a plan."""
MAX_WAYPOINTS = 4096
"""Axis ``T``: waypoints of a trajectory."""
MAX_JOINTS = 64
"""Axis ``D``: joints of a configuration or trajectory."""
MAX_GRID_DIM = 1024
"""Voxels along one axis of an occupancy grid."""
MAX_GRID_CELLS = 256 ** 3
"""Voxels of an occupancy grid, ``nx * ny * nz`` (a dense float32 copy is then at most 64 MiB); also
axis ``N``, the non-zero voxels sent."""
MAX_KEYPOINTS = 256
"""Axis ``J``: points of a keypoint frame (body trackers give 15 to 70; marker sets up to ~100)."""
AXIS_LIMITS: dict[str, int] = {"M": MAX_CLASSES, "K": MAX_GOALS, "T": MAX_WAYPOINTS, "D": MAX_JOINTS,
                               "N": MAX_GRID_CELLS, "J": MAX_KEYPOINTS}
"""The largest length of each named array axis (the symbols of docs/protocol.md)."""

# -- counters ---------------------------------------------------------------------------------------

MAX_TICK = 2 ** 31 - 1
"""Largest lock-step tick (and plan step): 13 years of 0.2 s steps."""
MAX_SAMPLES = 10_000_000
"""Largest sample index within a demonstration, and largest ``n_samples``."""
MAX_DEMO_ID = 2 ** 31 - 1
"""Largest demonstration number."""

# -- geometry and time ------------------------------------------------------------------------------

MIN_RESOLUTION_M = 0.005
"""Finest voxel edge of an occupancy grid (m); ``foresight train --resolution`` has the same range."""
MAX_RESOLUTION_M = 0.5
"""Coarsest voxel edge (m)."""
MAX_COORDINATE_M = 100.0
"""Largest |coordinate| of a grid origin in the scene frame (m)."""
MAX_KEYPOINT_M = 20.0
"""Largest |coordinate| of a body keypoint in its sensor's frame (m): a room-sized workcell and then some."""
MAX_FRAME = 2 ** 53
"""Largest keypoint frame number (a 1 kHz sensor runs 285 000 years before it reaches this)."""
MIN_PERIOD_S = 1e-3
"""Shortest lock-step period of a ClockTick (s)."""
MAX_PERIOD_S = 60.0
"""Longest lock-step period (s)."""
MIN_DT_S = 1e-4
"""Shortest time between two waypoints of a plan (s)."""
MAX_DT_S = 60.0
"""Longest time between two waypoints (s)."""
MAX_PLANNING_MS = 3.6e6
"""Longest planning time a plan may report (one hour)."""
MAX_ABS_COST = 1e12
"""Largest |cost| of a valid goal (the planner's costs are O(1) to O(1e4))."""

# -- the robot (when the receiver has no model of its own) ----------------------------------------

MAX_ABS_JOINT = 100.0
"""Largest |q| (rad or m) accepted from a robot the receiver has no model of."""
MAX_ABS_JOINT_VELOCITY = 100.0
"""Largest |qd| (rad/s or m/s) accepted from a robot the receiver has no model of."""
JOINT_LIMIT_TOL = 0.05
"""How far (rad or m) a configuration or waypoint may lie outside the receiver's joint limits."""
VELOCITY_LIMIT_TOL = 0.1
"""Relative excess over the receiver's joint velocity limits a state's ``qd`` may have (10 %)."""

# -- stamps -----------------------------------------------------------------------------------------

STAMP_FUTURE_S = 2.0
"""Real time: how far (s) a wall-clock stamp may lie ahead of the receiver's clock (skew)."""
STAMP_PAST_S = 120.0
"""Real time: how old (s) a wall-clock stamp may be on receipt (a first plan can take seconds)."""
MAX_LOGICAL_STAMP_S = 1e8
"""Lock-step: largest simulated time (s); any larger stamp is wall-clock time, not logical time."""
LOGICAL_STAMP_TOL_S = 1e-6
"""Lock-step: slack (s) on ``tick * P <= stamp <= (tick + 1) * P`` when the receiver knows P."""
CLOCK_STAMP_RTOL = 1e-9
"""Lock-step: relative tolerance of ``ClockTick.stamp == tick * period``."""
