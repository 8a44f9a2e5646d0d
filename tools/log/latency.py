"""Latencies of a run, from its MCAP log: pose -> occupancy -> plan, and the replanning period.

Every message in the executor's log carries the time the executor received it (``log_time``, one
clock for all), so differences between log times are end-to-end latencies across processes:

* pose -> occupancy: an OccupancyGrid's log time minus that of the HumanPose it was predicted from
  (same ``demo_id`` and ``index``);
* pose -> plan: a Plan's log time minus that of the newest pose its occupancy was predicted from
  (``occupancy_index``), i.e. how old the human's motion is that the published plan accounts for
  (only plans published while a demonstration streams: after its end marker no pose is new);
* occupancy -> plan: the same, from the OccupancyGrid the plan used;
* the replanning period achieved: differences between consecutive Plans' log times;
* planning time: ``Plan.planning_ms`` as the planner measured it;
* with the tracker in the loop (a ``HumanKeypoints`` channel): keypoints -> pose, a HumanPose's log time minus that
  of the keypoint frame it was fitted from (the frame with the pose's stamp; poses interpolated across a gap have
  none), and keypoints -> plan, from that frame to the plan. A reach's first poses (``pre_s`` of them) are published
  together when the reach is recognised, so they carry that wait.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from shared.protocol import DemoMarker, HumanKeypoints, HumanPose, OccupancyGrid, Plan, ProtocolError, decode
from shared.runtime import UserError

from .steps import run_topics
from .versions import check_readable

__all__ = ["Stat", "PlanSample", "run_latencies", "format_latencies", "slowest_plans", "format_slowest"]


@dataclass(frozen=True)
class Stat:
    """Summary of one latency series, milliseconds."""

    count: int
    p50: float
    p99: float
    max: float

    @classmethod
    def of(cls, values_ms: list[float]) -> Stat:
        """Median, 99th percentile and max of ``values_ms`` (NaN when empty)."""
        if not values_ms:
            return cls(0, float("nan"), float("nan"), float("nan"))
        a = np.asarray(values_ms, dtype=np.float64)
        return cls(len(a), float(np.percentile(a, 50)), float(np.percentile(a, 99)), float(a.max()))


@dataclass(frozen=True)
class PlanSample:
    """One plan's share of the pose -> plan series: where a late plan's time went.

    Attributes:
        step: ``Plan.step``.
        t_s: Seconds from the run's first pose to the plan's arrival.
        pose_to_plan_ms: From its newest pose's arrival to the plan's.
        occupancy_to_plan_ms: From its occupancy's arrival to the plan's (NaN: that occupancy is not in the log).
        planning_ms: ``Plan.planning_ms``, the step as the planner timed it.
    """

    step: int
    t_s: float
    pose_to_plan_ms: float
    occupancy_to_plan_ms: float
    planning_ms: float

    @property
    def not_planning_ms(self) -> float:
        """Occupancy -> plan less the planning: the wait for the step running when the occupancy came, and travel."""
        return self.occupancy_to_plan_ms - self.planning_ms


def run_latencies(messages: list[Any], topics: dict[str, str],
                  samples: list[PlanSample] | None = None) -> dict[str, Stat]:
    """Latency statistics of a run.

    Args:
        messages: Log messages with ``topic``, ``log_time`` (ns) and ``data`` (msgpack payload), in file order.
        topics: Topic of each message type: keys ``"pose"``, ``"occupancy"``, ``"plan"`` and optionally
            ``"demo"`` (DemoMarker: plans after a demonstration's end do not count for pose -> plan) and
            ``"keypoints"`` (HumanKeypoints: the tracker's input).
        samples: If given, one :class:`PlanSample` per plan of the pose -> plan series is appended.

    Returns:
        ``{"pose_to_occupancy", "pose_to_plan", "occupancy_to_plan", "replanning_period", "planning"}``, and with
        ``"keypoints"`` also ``"keypoints_to_pose"`` and ``"keypoints_to_plan"``.
    """
    pose_time: dict[tuple[int, int], int] = {}
    occ_time: dict[tuple[int, int], int] = {}
    pose_to_occ: list[float] = []
    pose_to_plan: list[float] = []
    occ_to_plan: list[float] = []
    plan_times: list[int] = []
    planning: list[float] = []
    frame_time: dict[float, int] = {}   # keypoint frame stamp -> its log time
    pose_frame: dict[tuple[int, int], int] = {}  # pose -> the log time of the frame it was fitted from
    kp_to_pose: list[float] = []
    kp_to_plan: list[float] = []
    current_demo = -1
    occ_demo: dict[int, int] = {}  # occupancy index -> the demonstration of the newest occupancy of that index
    first_pose: int | None = None
    streaming = True
    decoded, refused, relevant = 0, [], set(topics.values())
    for m in sorted(messages, key=lambda m: m.log_time):
        decoded += m.topic in relevant  # less the refused below
        try:
            if m.topic == topics.get("keypoints"):
                frame_time[decode(m.data, HumanKeypoints).stamp] = m.log_time
            elif m.topic == topics.get("demo"):
                streaming = decode(m.data, DemoMarker).event == "start"
            elif m.topic == topics["pose"]:
                pose = decode(m.data, HumanPose)
                pose_time[(pose.demo_id, pose.index)] = m.log_time
                first_pose = m.log_time if first_pose is None else first_pose
                current_demo = pose.demo_id
                t_frame = frame_time.get(pose.stamp)
                if t_frame is not None:
                    pose_frame[(pose.demo_id, pose.index)] = t_frame
                    kp_to_pose.append((m.log_time - t_frame) / 1e6)
            elif m.topic == topics["occupancy"]:
                occ = decode(m.data, OccupancyGrid)
                occ_time[(occ.demo_id, occ.index)] = m.log_time
                occ_demo[occ.index] = occ.demo_id
                t0 = pose_time.get((occ.demo_id, occ.index))
                if t0 is not None:
                    pose_to_occ.append((m.log_time - t0) / 1e6)
            elif m.topic == topics["plan"]:
                plan = decode(m.data, Plan)
                plan_times.append(m.log_time)
                planning.append(plan.planning_ms)
                # the demonstration of the occupancy it planned against (a plan names its index only), not the
                # newest pose's: in real time a plan can come after the next demonstration's first poses
                key = (occ_demo.get(plan.occupancy_index, current_demo), plan.occupancy_index)
                if not streaming:
                    continue
                occ_ms = (m.log_time - occ_time[key]) / 1e6 if key in occ_time else float("nan")
                if plan.occupancy_index >= 0 and key in pose_time:
                    pose_to_plan.append((m.log_time - pose_time[key]) / 1e6)
                    if samples is not None:
                        samples.append(PlanSample(plan.step, (m.log_time - (first_pose or 0)) / 1e9,
                                                  pose_to_plan[-1], occ_ms, plan.planning_ms))
                if plan.occupancy_index >= 0 and key in occ_time:
                    occ_to_plan.append(occ_ms)
                if plan.occupancy_index >= 0 and key in pose_frame:
                    kp_to_plan.append((m.log_time - pose_frame[key]) / 1e6)
        except ProtocolError as exc:
            decoded -= 1
            refused.append(exc)
    check_readable(decoded, refused)
    period = list(np.diff(np.asarray(plan_times, dtype=np.float64)) / 1e6)
    stats = {"pose_to_occupancy": Stat.of(pose_to_occ), "pose_to_plan": Stat.of(pose_to_plan),
             "occupancy_to_plan": Stat.of(occ_to_plan), "replanning_period": Stat.of(period),
             "planning": Stat.of(planning)}
    if "keypoints" in topics:
        stats |= {"keypoints_to_pose": Stat.of(kp_to_pose), "keypoints_to_plan": Stat.of(kp_to_plan)}
    return stats


def format_latencies(stats: dict[str, Stat]) -> str:
    """A table of :func:`run_latencies`' result."""
    lines = [f"{'latency (ms)':<22}{'count':>7}{'p50':>10}{'p99':>10}{'max':>10}"]
    for name, s in stats.items():
        cells = "".join(f"{v:>10.1f}" if math.isfinite(v) else f"{'-':>10}" for v in (s.p50, s.p99, s.max))
        lines.append(f"{name.replace('_', ' '):<22}{s.count:>7}{cells}")
    return "\n".join(lines)


def slowest_plans(samples: list[PlanSample], n: int) -> list[PlanSample]:
    """The ``n`` plans of ``samples`` with the longest pose -> plan, longest first (ties: the earlier first)."""
    return sorted(samples, key=lambda s: (-s.pose_to_plan_ms, s.t_s))[:max(n, 0)]


def format_slowest(slowest: list[PlanSample]) -> str:
    """A table of :func:`slowest_plans`: each late plan's time split into the step and the rest."""
    lines = ["slowest plans by pose -> plan (ms; not planning = occupancy -> plan less the step: the wait for the "
             "step running when the occupancy came, and the messages' travel)",
             f"{'plan':>6}{'t (s)':>8}{'pose -> plan':>14}{'occupancy -> plan':>19}{'planning':>10}"
             f"{'not planning':>14}"]
    for s in slowest:
        occ = f"{s.occupancy_to_plan_ms:>19.1f}" if math.isfinite(s.occupancy_to_plan_ms) else f"{'-':>19}"
        rest = f"{s.not_planning_ms:>14.1f}" if math.isfinite(s.not_planning_ms) else f"{'-':>14}"
        lines.append(f"{s.step:>6}{s.t_s:>8.2f}{s.pose_to_plan_ms:>14.1f}{occ}{s.planning_ms:>10.1f}{rest}")
    return "\n".join(lines)


def log_latencies(path: str | Path, read: list[Any] | None = None,
                  samples: list[PlanSample] | None = None) -> dict[str, Stat]:
    """:func:`run_latencies` of an MCAP log's Foresight channels.

    Args:
        path: The log.
        read: If given, the :class:`~shared.recording.reader.LogFile` read is appended (whether it was complete).
        samples: If given, each plan's :class:`PlanSample` is appended (see :func:`run_latencies`).

    Raises:
        ValueError: The log lacks the HumanPose, OccupancyGrid or Plan channel.
    """
    from shared.recording.reader import read_log

    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.DemoMarker",
              "foresight.HumanKeypoints"}
    lf = read_log(path, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    if read is not None:
        read.append(lf)
    topics = {}
    for key, schema in (("pose", "foresight.HumanPose"), ("occupancy", "foresight.OccupancyGrid"),
                        ("plan", "foresight.Plan"), ("demo", "foresight.DemoMarker"),
                        ("keypoints", "foresight.HumanKeypoints")):
        found = sorted(run_topics(lf, schema))  # the run's own key: a stray one of the schema took its place
        if len(found) > 1:
            raise ValueError(f"{path}: {schema.removeprefix('foresight.')} on {len(found)} keys ({', '.join(found)}) "
                             "and no run metadata naming the run's own among them")
        if found:
            topics[key] = found[0]
    if not {"pose", "occupancy", "plan"} <= set(topics):
        raise ValueError(f"{path}: needs HumanPose, OccupancyGrid and Plan channels, found {sorted(topics)}")
    try:
        return run_latencies(lf.messages, topics, samples)
    except UserError as exc:  # which log
        raise UserError(f"{path}: {exc}") from None
