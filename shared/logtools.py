"""``foresight log``: look at a run's MCAP log without Foxglove.

* ``foresight log info FILE [--json]``: header, time range, channels (topic, schema, encodings,
  message counts), attachments, metadata and rejected payloads. Works on a file whose writer was
  killed (everything up to the last complete chunk is read; the output says it is truncated).
* ``foresight log render FILE --step N --out PNG`` (or ``--all --out DIR``): draws replanning step N
  with matplotlib -- table, cups, the human's body, the occupied voxels coloured by probability, the
  robot's collision spheres and the K candidate end-effector paths, the chosen one highlighted --
  as a 3D view and a top view.

The reader (:func:`read_log`) goes through the file record by record (mcap's stream reader), so it
needs no summary section.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import struct
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from shared.protocol import HumanPose, OccupancyGrid, Plan, ProtocolError, RobotState, decode
from shared.runtime import UserError, cli_errors
from shared.scene import Scene, load_scene, parse_scene

__all__ = ["LogChannel", "LogMessage", "LogFile", "read_log", "format_info", "StepView", "step_views",
           "step_title", "render_step", "main"]


@dataclass
class LogChannel:
    """One channel of the log and what was read of it."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_size: int
    count: int = 0
    first_time: int | None = None
    last_time: int | None = None


@dataclass
class LogMessage:
    """One message: its channel's topic, times (ns) and raw payload."""

    topic: str
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class LogFile:
    """What :func:`read_log` found in an MCAP file.

    Attributes:
        complete: True when the footer was read (the writer finished the file).
        error: Why reading stopped early (truncated or damaged file), else "".
        messages: The kept messages in file order (see ``keep`` of :func:`read_log`).
    """

    path: str
    size: int
    profile: str = ""
    library: str = ""
    channels: dict[int, LogChannel] = field(default_factory=dict)
    messages: list[LogMessage] = field(default_factory=list)
    attachments: dict[str, bytes] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False
    error: str = ""

    @property
    def message_count(self) -> int:
        """Messages read on all channels."""
        return sum(c.count for c in self.channels.values())

    def topic_messages(self, topic: str) -> list[LogMessage]:
        """The kept messages of one topic."""
        return [m for m in self.messages if m.topic == topic]


def read_log(path: str | Path, keep: Callable[[LogChannel], bool] | None = None) -> LogFile:
    """Read an MCAP file record by record, tolerating a truncated end.

    Args:
        path: The file.
        keep: Keep the payloads of the channels for which it returns True (default: none; counts only).

    Raises:
        UserError: If the file is missing or not an MCAP file at all.
    """
    p = Path(path)
    if not p.is_file():
        raise UserError(f"log file {str(p)!r} not found")
    out = LogFile(str(p), p.stat().st_size)
    schemas: dict[int, Schema] = {}
    with p.open("rb") as f:
        reader = StreamReader(f, record_size_limit=1 << 31)
        try:
            for rec in reader.records:
                if isinstance(rec, Header):
                    out.profile, out.library = rec.profile, rec.library
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    if rec.id not in out.channels:
                        sc = schemas.get(rec.schema_id)
                        out.channels[rec.id] = LogChannel(rec.id, rec.topic, rec.message_encoding,
                                                          sc.name if sc else "", sc.encoding if sc else "",
                                                          len(sc.data) if sc else 0)
                elif isinstance(rec, Message):
                    ch = out.channels.get(rec.channel_id)
                    if ch is None:
                        raise McapError(f"message on unknown channel {rec.channel_id}")
                    ch.count += 1
                    ch.first_time = rec.log_time if ch.first_time is None else min(ch.first_time, rec.log_time)
                    ch.last_time = rec.log_time if ch.last_time is None else max(ch.last_time, rec.log_time)
                    if keep is not None and keep(ch):
                        out.messages.append(LogMessage(ch.topic, rec.log_time, rec.publish_time, bytes(rec.data)))
                elif isinstance(rec, Attachment):
                    out.attachments[rec.name] = bytes(rec.data)
                elif isinstance(rec, Metadata):
                    out.metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Footer):
                    out.complete = True
        except (McapError, struct.error, ValueError, EOFError) as exc:
            if not out.channels and not out.profile and not out.complete:
                if isinstance(exc, McapError) and "magic" in str(exc).lower():
                    raise UserError(f"{p}: not an MCAP file ({exc})") from None
            out.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return out


# ----------------------------------------------------------------------------------------------
# info


def _fmt_time(ns: int | None) -> str:
    if ns is None:
        return "-"
    return datetime.fromtimestamp(ns / 1e9, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "Z"


def info_dict(lf: LogFile) -> dict[str, Any]:
    """The summary :func:`format_info` prints, as a JSON-ready dict."""
    firsts = [c.first_time for c in lf.channels.values() if c.first_time is not None]
    lasts = [c.last_time for c in lf.channels.values() if c.last_time is not None]
    rejects = {k: int(v) for k, v in lf.metadata.get("foresight.rejects", {}).items()}
    return {
        "path": lf.path, "size_bytes": lf.size, "complete": lf.complete, "error": lf.error,
        "profile": lf.profile, "library": lf.library,
        "start": _fmt_time(min(firsts)) if firsts else None, "end": _fmt_time(max(lasts)) if lasts else None,
        "duration_s": (max(lasts) - min(firsts)) / 1e9 if firsts else 0.0,
        "messages": lf.message_count,
        "channels": [{"topic": c.topic, "schema": c.schema_name, "schema_encoding": c.schema_encoding,
                      "message_encoding": c.message_encoding, "messages": c.count}
                     for c in sorted(lf.channels.values(), key=lambda c: c.topic)],
        "attachments": {k: len(v) for k, v in lf.attachments.items()},
        "metadata": lf.metadata,
        "rejected": rejects,
    }


def format_info(lf: LogFile) -> str:
    """Human-readable summary: file state, time range, one line per channel, attachments, metadata."""
    d = info_dict(lf)
    state = "complete" if lf.complete else f"TRUNCATED ({lf.error or 'no footer'}): read up to the last whole chunk"
    lines = [f"file:      {lf.path} ({lf.size / 1e6:.2f} MB, {state})",
             f"profile:   {lf.profile or '-'}   library: {lf.library or '-'}",
             f"time:      {d['start']} .. {d['end']} ({d['duration_s']:.2f} s)",
             f"messages:  {d['messages']} on {len(lf.channels)} channels", ""]
    w = max([len(c["topic"]) for c in d["channels"]] + [5])
    ws = max([len(c["schema"]) for c in d["channels"]] + [6])
    lines.append(f"  {'topic':<{w}}  {'schema':<{ws}}  {'schema enc':<10}  {'msg enc':<8}  {'messages':>8}")
    for c in d["channels"]:
        lines.append(f"  {c['topic']:<{w}}  {c['schema']:<{ws}}  {c['schema_encoding']:<10}  "
                     f"{c['message_encoding']:<8}  {c['messages']:>8}")
    if lf.attachments:
        lines += ["", "attachments: " + ", ".join(f"{k} ({v} B)" for k, v in d["attachments"].items())]
    run = lf.metadata.get("foresight.run")
    if run:
        keys = ("mode", "steps", "step_period_s", "stale_limit_s", "prefix")
        lines += ["", "run:       " + "  ".join(f"{k}={run[k]}" for k in keys if k in run)]
    if "foresight.rejects" in lf.metadata:
        rej = d["rejected"]
        lines += ["rejected:  " + (", ".join(f"{k}: {v}" for k, v in sorted(rej.items())) if rej else "none")]
    elif not lf.complete:
        lines += ["rejected:  (counts are written when the file is closed)"]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# render


@dataclass
class StepView:
    """Everything drawn for one replanning step (decoded from the log).

    ``t0`` is the start of the run on the messages' clock: 0 in lock-step (simulated time), the
    first robot state's wall-clock stamp in real time; times in titles count from it.
    """

    plan: Plan
    occupancy: OccupancyGrid | None
    pose: HumanPose | None
    first_pose: HumanPose | None
    state: RobotState | None
    t0: float = 0.0


def _decode_all(lf: LogFile, schema: str, cls: type) -> list[tuple[int, Any]]:
    topics = {c.topic for c in lf.channels.values() if c.schema_name == schema and c.message_encoding == "msgpack"}
    out = []
    for m in lf.messages:
        if m.topic in topics:
            try:
                out.append((m.log_time, decode(m.data, cls)))
            except ProtocolError:
                continue  # only valid payloads are on these channels; be tolerant anyway
    return out


def _latest_before(items: list[tuple[int, Any]], t: int, pred: Callable[[Any], bool] = lambda _: True) -> Any:
    best = None
    for lt, msg in items:
        if lt <= t and pred(msg):
            best = msg
    return best


def step_views(lf: LogFile) -> dict[int, StepView]:
    """One :class:`StepView` per replanning step (``Plan.step``) in the log (the last plan of a step wins)."""
    plans = _decode_all(lf, "foresight.Plan", Plan)
    occs = _decode_all(lf, "foresight.OccupancyGrid", OccupancyGrid)
    poses = _decode_all(lf, "foresight.HumanPose", HumanPose)
    states = _decode_all(lf, "foresight.RobotState", RobotState)
    realtime = bool(plans) and all(p.tick < 0 for _, p in plans)
    t0 = 0.0
    if realtime:
        t0 = min([s.stamp for _, s in states] or [p.stamp for _, p in plans])
    views: dict[int, StepView] = {}
    for lt, plan in plans:
        occ = _latest_before(occs, lt, lambda o, p=plan: o.tick == p.occupancy_tick and o.index == p.occupancy_index)
        occ = occ or _latest_before(occs, lt)
        pose = None
        if occ is not None:
            pose = _latest_before(poses, lt, lambda h, o=occ: h.demo_id == o.demo_id and h.index == o.index)
        pose = pose or _latest_before(poses, lt)
        first = None
        if pose is not None:
            same = [h for _, h in poses if h.demo_id == pose.demo_id]
            first = min(same, key=lambda h: h.index) if same else pose
        views[plan.step] = StepView(plan, occ, pose, first, _latest_before(states, lt), t0)
    return views


def _scene_of(lf: LogFile) -> Scene:
    text = lf.attachments.get("scene.toml")
    if text is None:
        return load_scene(None)
    return parse_scene(tomllib.loads(text.decode()), "scene.toml (attached)")


_GOAL_COLORS = {"blue": "#2659f2", "red": "#e62626", "green": "#1ab233", "yellow": "#e6cc1a"}


def _goal_color(name: str, k: int) -> str:
    for word, col in _GOAL_COLORS.items():
        if word in name.lower():
            return col
    return ["#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2"][k % 5]


def _robot_geometry(view: StepView, scene: Scene, robot: Any) -> tuple[np.ndarray | None, np.ndarray | None,
                                                                        np.ndarray | None]:
    """(sphere centres (S,3), radii (S,), end-effector paths (K,T,3)) from the robot model."""
    import torch

    names = list(robot.joint_names)

    def order(q: np.ndarray, msg_names: list[str]) -> np.ndarray:
        return q[..., [list(msg_names).index(n) for n in names]]

    def tens(q: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(q, dtype=robot.lower.dtype, device=robot.lower.device)

    centers = radii = None
    if view.state is not None and sorted(view.state.joint_names) == sorted(names):
        centers = robot.sphere_centers(tens(order(view.state.q, view.state.joint_names))).detach().cpu().numpy()
        radii = robot.sphere_radii.detach().cpu().numpy()
    paths = None
    if sorted(view.plan.joint_names) == sorted(names):
        q = order(view.plan.trajectories.astype(np.float64), view.plan.joint_names)
        paths = robot.end_effector(tens(q)).detach().cpu().numpy()[..., :3, 3]
    return centers, radii, paths


def _human_geometry(view: StepView, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    if view.pose is None:
        return None
    from shared.human import HumanModel, place_in_scene

    first = view.first_pose.features if view.first_pose is not None else view.pose.features
    feats = place_in_scene(view.pose.features, first, scene)
    ends, radii = HumanModel().capsules(feats)
    return np.asarray(ends), np.asarray(radii)


def step_title(view: StepView) -> str:
    """The two-line title of a rendered step.

    Step, time (simulated in lock-step, seconds into the run in real time, never a raw epoch), choice,
    costs and planning time; then the occupancy drawn and the robot's state.
    """
    plan, occ, t0 = view.plan, view.occupancy, view.t0
    costs = ", ".join(f"{g}={c:.3g}" for g, c in zip(plan.goal_names, plan.cost_total, strict=True))
    when = f"tick {plan.tick}, " if plan.tick >= 0 else ""
    when += f"t = {plan.stamp - t0:.2f} s" + (" simulated" if plan.tick >= 0 else " into the run")
    if occ is None:
        occ_txt = "no occupancy logged"
    elif occ.tick >= 0:
        occ_txt = f"occupancy of tick {occ.tick} / pose {occ.index} ({occ.method})"
    else:
        occ_txt = f"occupancy of pose {occ.index} at t = {occ.stamp - t0:.2f} s ({occ.method})"
    state_txt = ""
    if view.state is not None:
        state_txt = f"; robot {'HOLDING: ' + view.state.reason if view.state.holding else 'moving'}"
    return (f"Replanning step {plan.step} ({when}): chosen {plan.goal_names[plan.chosen]}; cost {costs}; "
            f"planning {plan.planning_ms:.0f} ms\n{occ_txt}{state_txt}")


def render_step(view: StepView, scene: Scene, out: str | Path, robot: Any = None, min_probability: float = 0.05,
                dpi: int = 110) -> Path:
    """Draw one replanning step (3D view and top view) to a PNG.

    Args:
        view: The step's messages.
        scene: The scene (table, cups).
        out: PNG path (parent directories are created).
        robot: Robot model for the spheres and end-effector paths (default: shared.robot.PR2 in the scene).
        min_probability: Voxels below this are not drawn.
        dpi: Resolution.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if robot is None:
        import torch

        from shared.robot import PR2

        robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    plan = view.plan
    centers, radii, paths = _robot_geometry(view, scene, robot)
    human = _human_geometry(view, scene)

    fig = plt.figure(figsize=(15, 7.2))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    lo = np.array([-1.0, -2.0, 0.0])
    hi = np.array([1.4, 0.4, 2.0])
    lo, hi = np.minimum(lo, scene.grid.min), np.maximum(hi, scene.grid.max)

    # table and other boxes
    for b in scene.boxes:
        x0, y0, z0 = b.lower
        x1, y1, z1 = b.upper
        top = [[(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]]
        ax3.add_collection3d(Poly3DCollection(top, facecolor="#b08050", alpha=0.35, edgecolor="#6b4a2a"))
        ax2.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="#d9b38c", edgecolor="#6b4a2a", alpha=0.6,
                                zorder=0, label=b.name))
    # cups
    for k, cup in enumerate(scene.cups):
        col = _goal_color(cup.name, k)
        th = np.linspace(0, 2 * np.pi, 24)
        for z in (cup.position[2], cup.position[2] + cup.height):
            ax3.plot(cup.position[0] + cup.radius * np.cos(th), cup.position[1] + cup.radius * np.sin(th),
                     np.full_like(th, z), color=col, lw=1.5)
        ax2.add_patch(Circle(tuple(cup.position[:2]), cup.radius, color=col, zorder=4, label=cup.name))

    # occupancy
    occ = view.occupancy
    if occ is not None:
        p = occ.values.astype(np.float64) / 255.0
        keep = p >= min_probability
        ijk = np.stack(np.unravel_index(occ.indices[keep].astype(np.int64), tuple(int(d) for d in occ.dims)), -1)
        c = occ.origin + occ.resolution * (ijk + 0.5)
        pk = p[keep]
        order = np.argsort(pk)
        if c.size:
            ax3.scatter(c[order, 0], c[order, 1], c[order, 2], c=pk[order], cmap="YlOrRd", vmin=0, vmax=1,
                             s=10, alpha=0.25, depthshade=False, linewidths=0)
            # top view: the most probable voxel of each (x, y) column
            cols: dict[tuple[int, int], float] = {}
            for (i, j, _), v in zip(ijk, pk, strict=True):
                cols[(i, j)] = max(cols.get((i, j), 0.0), v)
            ij = np.array(list(cols))
            v = np.array(list(cols.values()))
            o = np.argsort(v)
            ax2.scatter(occ.origin[0] + occ.resolution * (ij[o, 0] + 0.5),
                        occ.origin[1] + occ.resolution * (ij[o, 1] + 0.5), c=v[o], cmap="YlOrRd", vmin=0,
                        vmax=1, marker="s", s=28, alpha=0.6, linewidths=0, zorder=1)
            from matplotlib.cm import ScalarMappable
            from matplotlib.colors import Normalize

            fig.colorbar(ScalarMappable(Normalize(0, 1), "YlOrRd"), ax=ax2, shrink=0.7,
                         label="predicted occupancy p(x|ξ) (top view: column max)")

    span = float(np.max(hi - lo))
    pts_per_m = 0.45 * 7.2 * 72 / span  # rough size of a metre in points in the 3D view
    # human body: capsules (3D: thick lines; top view: the capsules' footprints)
    if human is not None:
        ends, hr = human
        for (a, b_), r in zip(ends, hr, strict=True):
            ax3.plot(*zip(a, b_, strict=True), color="#3060d0", lw=max(1.5, 2 * r * pts_per_m), alpha=0.6,
                     solid_capstyle="round")
            for s in np.linspace(0.0, 1.0, 6):
                c = a + s * (b_ - a)
                ax2.add_patch(Circle((c[0], c[1]), r, facecolor="#3060d0", edgecolor="none", alpha=0.18,
                                     zorder=3))
            ax2.plot([a[0], b_[0]], [a[1], b_[1]], color="#1a3a90", lw=1.2, zorder=3)
        ax2.plot([], [], color="#3060d0", lw=4, label="human body")

    # robot spheres
    if centers is not None and radii is not None:
        ax3.scatter(centers[:, 0], centers[:, 1], centers[:, 2], s=(2 * radii * pts_per_m) ** 2,
                    color="#8a8a9a", alpha=0.35, edgecolors="#555", linewidths=0.3)
        for cc, r in zip(centers, radii, strict=True):
            ax2.add_patch(Circle(tuple(cc[:2]), r, facecolor="#9a9aaa", edgecolor="#555", alpha=0.25, lw=0.3,
                                 zorder=2))
        ax2.plot([], [], "o", color="#9a9aaa", label="robot spheres")

    # candidate paths
    if paths is not None:
        for k in range(paths.shape[0]):
            chosen = k == plan.chosen
            col = "#10c040" if chosen else _goal_color(plan.goal_names[k], k)
            ls = "-" if chosen else ("--" if bool(plan.valid[k]) else ":")
            lw = 4.0 if chosen else 1.8
            label = (f"{plan.goal_names[k]}{' (chosen)' if chosen else ''}{'' if plan.valid[k] else ' (invalid)'}: "
                     f"cost {plan.cost_total[k]:.3g}")
            ax3.plot(paths[k, :, 0], paths[k, :, 1], paths[k, :, 2], ls, color=col, lw=lw, zorder=10)
            ax2.plot(paths[k, :, 0], paths[k, :, 1], ls, color=col, lw=lw, zorder=6, label=label)
            ax2.plot(paths[k, -1, 0], paths[k, -1, 1], "*", color=col, ms=12, zorder=7)
        ax3.scatter(*paths[0, 0], color="k", s=25)
        ax2.plot(paths[0, 0, 0], paths[0, 0, 1], "ko", ms=5, zorder=7, label="end effector now")

    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(lo[2], hi[2])
    ax3.set_box_aspect(tuple(hi - lo))
    ax3.view_init(elev=28, azim=-50)
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax2.set_xlim(lo[0], hi[0])
    ax2.set_ylim(lo[1], hi[1])
    ax2.set_aspect("equal")
    ax2.set_xlabel("x (m)")
    ax2.set_ylabel("y (m)")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="upper left", fontsize=8, framealpha=0.85)
    fig.suptitle(step_title(view), fontsize=11)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out


# ----------------------------------------------------------------------------------------------
# CLI


def _main_info(args: argparse.Namespace) -> int:
    lf = read_log(args.file)
    if args.json:
        print(json.dumps(info_dict(lf), indent=2))
    else:
        print(format_info(lf))
    return 0


def _main_render(args: argparse.Namespace, prog: str) -> int:
    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.RobotState"}
    lf = read_log(args.file, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    views = step_views(lf)
    if not views:
        raise UserError(f"{args.file}: no Plan messages in the log, nothing to render")
    scene = _scene_of(lf)
    if args.all:
        steps = sorted(views)
    else:
        if args.step is None:
            raise UserError("give --step N or --all")
        if args.step not in views:
            raise UserError(f"{args.file}: no plan for step {args.step} (steps {min(views)}..{max(views)})")
        steps = [args.step]
    import torch

    from shared.robot import PR2

    robot = PR2.from_scene(scene, device="cpu", dtype=torch.float32)
    for n in steps:
        out = Path(args.out) / f"step_{n:03d}.png" if args.all else Path(args.out)
        render_step(views[n], scene, out, robot=robot, min_probability=args.min_probability)
        print(out)
    if not lf.complete:
        print(f"{prog}: note: {args.file} is truncated ({lf.error or 'no footer'})", file=sys.stderr)
    return 0


def _main_latency(args: argparse.Namespace) -> int:
    from shared.latency import format_latencies, run_latencies

    wanted = {"foresight.Plan", "foresight.OccupancyGrid", "foresight.HumanPose", "foresight.DemoMarker"}
    lf = read_log(args.file, keep=lambda ch: ch.schema_name in wanted and ch.message_encoding == "msgpack")
    topics = {}
    for ch in lf.channels.values():
        for key, schema in (("pose", "foresight.HumanPose"), ("occupancy", "foresight.OccupancyGrid"),
                            ("plan", "foresight.Plan"), ("demo", "foresight.DemoMarker")):
            if ch.schema_name == schema and ch.message_encoding == "msgpack":
                topics[key] = ch.topic
    if not {"pose", "occupancy", "plan"} <= set(topics):
        raise UserError(f"{args.file}: needs HumanPose, OccupancyGrid and Plan channels, found {sorted(topics)}")
    stats = run_latencies(lf.messages, topics)
    if args.json:
        print(json.dumps({k: dataclasses.asdict(v) for k, v in stats.items()}))
    else:
        print(format_latencies(stats))
    return 0


def main(argv: list[str] | None = None, prog: str = "foresight log") -> int:
    """``foresight log info|render|latency``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description="Look at a run's MCAP log without Foxglove: 'info' "
                                     "lists channels, schemas and message counts; 'render' draws replanning steps "
                                     "to PNG (table, cups, human, predicted occupancy, robot spheres, candidate "
                                     "end-effector paths); 'latency' measures pose -> occupancy -> plan.")
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="{info,render,latency}")
    pi = sub.add_parser("info", help="channels, schemas and message counts of an MCAP log")
    pi.add_argument("file", help="MCAP file")
    pi.add_argument("--json", action="store_true", help="print one JSON object")
    pr = sub.add_parser("render", help="draw replanning step(s) to PNG")
    pr.add_argument("file", help="MCAP file")
    pr.add_argument("--step", type=int, default=None, help="replanning step (Plan.step) to draw")
    pr.add_argument("--all", action="store_true", help="draw every step; --out is then a directory")
    pr.add_argument("--out", required=True, help="PNG path (or directory with --all)")
    pr.add_argument("--min-probability", type=float, default=0.05, help="hide voxels below this probability")
    pl = sub.add_parser("latency", help="pose -> occupancy -> plan latencies and the replanning period (p50, p99)")
    pl.add_argument("file", help="MCAP file")
    pl.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    with cli_errors(prog):
        if args.cmd == "info":
            return _main_info(args)
        if args.cmd == "latency":
            return _main_latency(args)
        if not (0.0 <= args.min_probability <= 1.0) or math.isnan(args.min_probability):
            raise UserError(f"--min-probability must be in [0, 1], got {args.min_probability}")
        return _main_render(args, prog)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
