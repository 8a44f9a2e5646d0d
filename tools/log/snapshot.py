"""``foresight log snapshot``: the logged 3D scene at a moment of the run, as Foxglove would show it, to a PNG.

Drawn from the scene channels only (:func:`shared.foxglove.decode.read_scene`), never from Foresight's own
messages: :func:`scene_at` replays them up to a time (the latest message per topic, scene entities replaced
by id) and :func:`draw_snapshot` draws the table, cups, robot spheres, candidate paths, the human and the
occupancy cloud in a perspective view and a top view.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shared.atomic_file import make_parent
from shared.belief import recognised_class
from shared.foxglove.decode import SceneDecodeError, SceneRecord, read_scene
from shared.recording.reader import DAMAGED
from shared.runtime import UserError

__all__ = ["SceneState", "scene_at", "draw_snapshot"]

_NUMERIC = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<f4", 8: "<f8"}  # PackedElementField
_ALL = 1  # SceneEntityDeletion.Type.ALL (0: MATCHING_ID)


@dataclass
class SceneState:
    """What the scene channels show at one moment of a log.

    Attributes:
        t_s: The moment, seconds from the first scene record.
        entities: Topic -> entity id -> ``foxglove.SceneEntity`` (the latest of each id, unless its lifetime ended
            before the moment, as Foxglove removes it).
        voxels: ``(N, 3)`` occupancy cloud points (m, world frame).
        probability: ``(N,)`` their probabilities (1 if the cloud has none).
        rgba: ``(N, 4)`` their colours (uint8).
        frames: Child frame -> ``(3,)`` translation from ``/tf``.
        posterior: The latest ``/viz/posterior`` object, or None.
        costs: The latest ``/viz/costs`` object, or None.
    """

    t_s: float = 0.0
    entities: dict[str, dict[str, Any]] = field(default_factory=dict)
    voxels: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    probability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rgba: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.uint8))
    frames: dict[str, np.ndarray] = field(default_factory=dict)
    posterior: dict[str, Any] | None = None
    costs: dict[str, Any] | None = None

    def entity(self, entity_id: str) -> Any | None:
        """The entity ``entity_id`` on any topic, or None."""
        return next((by_id[entity_id] for by_id in self.entities.values() if entity_id in by_id), None)

    def summary(self) -> str:
        """``t=..s, N voxels, chosen GOAL, recognised CLASS (p=..)``; ``recognised none (flat, p=..)`` as the table."""
        chosen = (self.costs or {}).get("chosen") or "-"
        step = f"step {self.costs['step']}, " if self.costs and "step" in self.costs else ""
        rec = "recognised -"
        post = self.posterior or {}
        probs = post.get("probability")
        if isinstance(probs, dict) and probs and all(isinstance(v, int | float) for v in probs.values()):
            # the table's rule on the plotted probabilities (a log written before 2026-11-29 named the top class
            # of a flat posterior in "recognised")
            name = recognised_class(list(probs), list(probs.values()))
            top = max(probs.values())
            rec = f"recognised {name} (p={top:.2f})" if name else f"recognised none (flat, p={top:.2f})"
        elif post.get("recognised"):
            name = post["recognised"]
            p = post.get("recognised_probability")
            rec = f"recognised {name}" + (f" (p={p:.2f})" if isinstance(p, int | float) else "")
        return f"t={self.t_s:.3f}s, {len(self.voxels)} voxels, {step}chosen {chosen}, {rec}"


def _cloud(state: SceneState, cloud: Any) -> None:
    """Set the state's voxels from a ``foxglove.PointCloud`` (fields by name, e.g. :data:`CLOUD_FIELDS`)."""
    fields, stride = [f for f in cloud.fields if f.type in _NUMERIC], int(cloud.point_stride)
    try:
        dtype = np.dtype({"names": [f.name for f in fields], "formats": [_NUMERIC[f.type] for f in fields],
                          "offsets": [f.offset for f in fields], "itemsize": stride})
        pts, names = np.frombuffer(cloud.data, dtype, count=len(cloud.data) // stride), set(dtype.names or ())
    except (ValueError, TypeError, ZeroDivisionError) as exc:
        raise SceneDecodeError(f"/viz/occupancy: a point layout numpy cannot read ({exc})") from None
    if not {"x", "y", "z"} <= names:
        return
    xyz = np.stack([pts[k] for k in "xyz"], -1).astype(np.float64)
    state.voxels = xyz @ _rotation(cloud.pose.orientation).T + _xyz(cloud.pose.position)
    state.probability = pts["probability"].astype(np.float64) if "probability" in names else np.ones(len(pts))
    state.rgba = np.stack([pts[k] if k in names else np.full(len(pts), 200)  # grey where a channel is missing
                           for k in ("red", "green", "blue", "alpha")], -1).astype(np.uint8)


_AT_MAX_S = 1e9
"""``--at`` beyond this (about 32 years) is read as this: later than any log's end, and a finite nanosecond count."""


def scene_at(path: str | Path, at_s: float | None) -> SceneState:
    """Replay a log's scene channels up to ``at_s`` seconds after its first scene record (None: the last plan).

    The latest message of each topic wins; a ``SceneUpdate``'s entities replace those of the same id.

    Raises:
        UserError: The file is missing, not an MCAP file or has no scene channels, or ``at_s`` is negative. A time
            past the scene's last record draws the last state (``t_s`` says when that is).
        SceneDecodeError: A scene message does not decode under its channel's schema.
    """
    p = Path(path)
    if at_s is not None and not (at_s >= 0.0 and math.isfinite(at_s)):
        raise UserError(f"--at must be a finite time >= 0 s, got {at_s}")
    end = math.inf
    if at_s is None:  # a first pass for the last plan's time
        end = max((r.log_time for r in _records(p, {"/viz/plan"})), default=math.inf)
    state, t0, last, cloud = SceneState(), None, None, None
    expiry: dict[tuple[str, str], int] = {}  # (topic, id) -> log time its lifetime ends (keypoints: 0.5 s)
    for r in _records(p):
        if t0 is None:
            # past any log's end it draws the last state: 1e300 s overflowed in round() (a traceback)
            t0, end = r.log_time, (end if at_s is None else r.log_time + round(min(at_s, _AT_MAX_S) * 1e9))
        last = r.log_time
        if r.log_time > end:
            break
        m = r.message
        if isinstance(m, dict):
            setattr(state, "posterior" if r.topic == "/viz/posterior" else "costs", m)
        elif r.schema_name == "foxglove.SceneUpdate":
            by_id = state.entities.setdefault(r.topic, {})
            for d in m.deletions:  # type: ignore[attr-defined]
                if d.type == _ALL:
                    by_id.clear()
                else:
                    by_id.pop(d.id, None)
            by_id.update({e.id: e for e in m.entities})  # type: ignore[attr-defined]
            for e in m.entities:  # type: ignore[attr-defined]
                life_ns = e.lifetime.ToNanoseconds() if e.HasField("lifetime") else 0
                expiry[(r.topic, e.id)] = r.log_time + life_ns if life_ns > 0 else math.inf
        elif r.schema_name == "foxglove.FrameTransforms":
            state.frames.update({t.child_frame_id: _xyz(t.translation) for t in m.transforms})  # type: ignore[attr-defined]
        elif r.schema_name == "foxglove.PointCloud":
            cloud = m
    if t0 is None or last is None:
        raise UserError(f"{p}: no scene channels (/viz/..., /tf) in the log, nothing to draw")
    if cloud is not None:
        _cloud(state, cloud)
    for topic, by_id in state.entities.items():  # what Foxglove has removed by then (keypoints the tracker lost)
        for gone in [i for i in by_id if expiry.get((topic, i), math.inf) < min(end, last)]:
            del by_id[gone]
    state.t_s = (min(end, last) - t0) / 1e9
    return state


def _records(path: Path, topics: set[str] | None = None) -> Iterator[SceneRecord]:
    """:func:`read_scene`, its read errors as one :class:`UserError` (a log without its summary is unreadable)."""
    try:
        yield from read_scene(path, topics)
    except SceneDecodeError:
        raise
    except (*DAMAGED, OSError) as exc:
        why = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise UserError(f"{path}: not a readable MCAP file, or truncated ({why})") from None


def _xyz(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=np.float64)


def _rgba(c: Any) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)


def _rotation(q: Any) -> np.ndarray:
    """The rotation matrix of a quaternion (Rodrigues; the zero quaternion is the identity)."""
    v, k = np.array([q.x, q.y, q.z]), np.cross([q.x, q.y, q.z], np.eye(3)).T  # k @ u == v x u
    return np.eye(3) + 2.0 / (float(v @ v + q.w * q.w) or 1.0) * (q.w * k + k @ k)


def _path_label(costs: dict[str, Any] | None, k: int, n: int) -> str | None:
    """``GOAL (chosen): cost C`` of path ``k`` of ``n``, when the costs name ``n`` goals (in the paths' order)."""
    total = (costs or {}).get("total") or {}
    if len(total) != n:
        return None
    goal, cost = list(total.items())[k]
    chosen = " (chosen)" if goal == costs.get("chosen") else ""  # type: ignore[union-attr]
    return f"{goal}{chosen}: cost {'invalid' if cost is None else format(cost, '.3g')}"


def draw_snapshot(state: SceneState, out_png: str | Path, title: str | None = None, dpi: int = 110) -> Path:
    """Draw ``state`` (a perspective 3D view and a top view, equal axis scales) to a PNG.

    Args:
        state: The scene (:func:`scene_at`).
        out_png: PNG path (parent directories are created).
        title: First title line (e.g. the log's name); the second is :meth:`SceneState.summary`.
        dpi: Resolution.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(15, 7.2))
    ax3, ax2 = fig.add_subplot(1, 2, 1, projection="3d"), fig.add_subplot(1, 2, 2)
    ents = [e for by_id in state.entities.values() for e in by_id.values()]
    pts = [state.voxels, *state.frames.values()]
    metric: list[tuple[Any, np.ndarray]] = []  # 3D artists sized in metres: (sphere scatter or limb, size)
    limbs: list[tuple[Any, float]] = []  # the top view's limbs and their thickness (m)
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    sign = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) / 2
    for e in ents:
        for c in e.cubes:
            corners = _xyz(c.pose.position) + (sign * _xyz(c.size)) @ _rotation(c.pose.orientation).T
            pts.append(corners)
            ax3.add_collection3d(Poly3DCollection([corners[list(f)] for f in faces], facecolor=_rgba(c.color),
                                                  edgecolor="#6b4a2a", linewidths=0.4, alpha=0.35))
            ax2.add_patch(Polygon(corners[[1, 3, 7, 5], :2], facecolor=_rgba(c.color), edgecolor="#6b4a2a",
                                  alpha=0.5, zorder=0))
        for c in e.cylinders:
            ctr, size, col = _xyz(c.pose.position), _xyz(c.size), _rgba(c.color)
            th, z = np.meshgrid(np.linspace(0, 2 * np.pi, 24), ctr[2] + np.array([-0.5, 0.5]) * size[2])
            ax3.plot_surface(ctr[0] + size[0] / 2 * np.cos(th), ctr[1] + size[1] / 2 * np.sin(th), z, color=col[:3])
            ax2.add_patch(Circle(tuple(ctr[:2]), size[0] / 2, color=col[:3], zorder=4, label=e.id.split("/")[-1]))
            pts.append(ctr[None])
        if e.spheres:
            ctr = np.array([_xyz(s.pose.position) for s in e.spheres])
            r, cols = np.array([s.size.x / 2 for s in e.spheres]), [_rgba(s.color) for s in e.spheres]
            metric.append((ax3.scatter(*ctr.T, c=cols, edgecolors="#555", linewidths=0.3), 2 * r))
            for cc, rr, col in zip(ctr, r, cols, strict=True):
                ax2.add_patch(Circle(tuple(cc[:2]), rr, facecolor=col, edgecolor="#555", lw=0.3, zorder=2))
            ax2.plot([], [], "o", color=cols[0][:3], label=e.id)
            pts.append(ctr)
        for k, ln in enumerate(e.lines):
            xyz = (np.array([_xyz(p) for p in ln.points]).reshape(-1, 3) @ _rotation(ln.pose.orientation).T
                   + _xyz(ln.pose.position))
            limb = e.id.startswith("human")
            lw = 2.0 if limb else 1.0 + 150.0 * ln.thickness  # a path's few mm, exaggerated to be seen
            label = (e.id if k == 0 else None) if limb else _path_label(state.costs, k, len(e.lines))
            (line,) = ax3.plot(*xyz.T, color=_rgba(ln.color), lw=lw, solid_capstyle="round", zorder=10)
            metric += [(line, np.array(ln.thickness))] if limb else []
            (top,) = ax2.plot(*xyz[:, :2].T, color=_rgba(ln.color), lw=lw, solid_capstyle="round", zorder=6,
                              label=label)
            limbs += [(top, ln.thickness)] if limb else []
            if not limb and len(xyz):
                ax2.plot(*xyz[-1, :2], "*", color=_rgba(ln.color)[:3], ms=10, zorder=7)
            pts.append(xyz)
    if len(state.voxels):
        o = np.argsort(state.probability)
        v, col = state.voxels[o], state.rgba[o] / 255.0
        ax3.scatter(*v.T, c=col, s=10, depthshade=False, linewidths=0)
        ax2.scatter(*v[:, :2].T, c=col, marker="s", s=24, linewidths=0, zorder=1, label=f"{len(v)} voxels")
    for name, t in state.frames.items():  # each /tf frame named where it is (the base's "+" read as a second hand)
        ax3.scatter(*t, color="k", s=20)
        ax2.plot(*t[:2], "k+", ms=8, zorder=8, label="frames (/tf)" if name == next(iter(state.frames)) else None)
        ax2.annotate(name, t[:2], xytext=(4, -10), textcoords="offset points", fontsize=7, zorder=8)
    allp = np.concatenate([np.reshape(p, (-1, 3)) for p in pts] + [np.zeros((1, 3))])  # the floor's origin too
    lo, hi = allp.min(0) - 0.1, allp.max(0) + 0.1
    pts_per_m = 0.45 * 7.2 * 72 / float(np.max(hi - lo))  # roughly, a metre in points in the 3D view
    for artist, size in metric:
        _ = artist.set_sizes((size * pts_per_m) ** 2) if size.ndim else artist.set_linewidth(size * pts_per_m)
    ax3.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]), xlabel="x (m)", ylabel="y (m)",
            zlabel="z (m)")
    ax3.set_box_aspect(tuple(hi - lo))
    ax3.view_init(elev=28, azim=-50)
    ax2.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), xlabel="x (m)", ylabel="y (m)", aspect="equal")
    ax2.grid(alpha=0.3)
    if ax2.get_legend_handles_labels()[0]:
        ax2.legend(loc="upper left", fontsize=8, framealpha=0.85)
    fig.suptitle("\n".join(s for s in (title, state.summary()) if s), fontsize=11)
    fig.tight_layout()
    bb = ax2.get_window_extent()  # the top view's scale in points per metre (equal aspect)
    for line, thickness in limbs:
        line.set_linewidth(thickness * min(bb.width / (hi - lo)[0], bb.height / (hi - lo)[1]) * 72 / fig.dpi)
    out = make_parent(out_png)  # a file in the way named (mkdir said "File exists")
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
