"""What one replanning step of a logged run shows: the plan and the messages it was made from.

:func:`step_views` pairs every ``Plan`` in a log with the occupancy it was computed on, the pose that
occupancy was predicted from (and its demonstration's first pose, to place the body in the scene)
and the robot's state; :func:`step_title` says in two lines what a rendered step shows.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from shared.protocol import HumanPose, Keys, OccupancyGrid, Plan, ProtocolError, RobotState, decode
from shared.recording.reader import LogFile
from shared.runtime import UserError
from shared.scene import Scene, load_scene, parse_scene

from .versions import check_readable

__all__ = ["StepView", "step_views", "step_title", "scene_of", "decode_all", "run_topics"]


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
    number: int | None = None  # real time: the plan's row in ``foresight log table`` (None: lock-step's step)


def run_topics(lf: LogFile, schema: str) -> set[str]:
    """The topics of ``schema``'s messages (Foresight's msgpack channels): the run's own key where the log has it.

    The executor logs any valid message under the prefix on a channel of its own, so a message of the type put on
    another key (a test's, a stray publisher's) has a channel of the same schema; it is not the run's.
    """
    topics = {c.topic for c in lf.channels.values() if c.schema_name == schema and c.message_encoding == "msgpack"}
    prefix = lf.metadata.get("foresight.run", {}).get("prefix")
    own = {f"foresight.{t.TYPE}": key for key, t in Keys(prefix).data_keys().items()}.get(schema) if prefix else None
    return {own} if own in topics else topics


def decode_all(lf: LogFile, schema: str, cls: type, required: bool = False) -> list[tuple[int, Any]]:
    """``(log time ns, message)`` of every valid message of ``schema`` on its key (Foresight's msgpack channels).

    Args:
        lf: The log, read with these channels kept.
        schema: The channels' schema name (``foresight.Plan``).
        cls: The message type.
        required: What the tool is made of (the plans): some logged and none decodable is an error naming the first
            fault; the tools said "no plans logged" and "no Plan messages in the log" (a review).

    Raises:
        UserError: Every message is of a schema version this build does not read, or ``required`` and none decode.
    """
    topics = run_topics(lf, schema)
    out, refused = [], []
    for m in lf.messages:
        if m.topic in topics:
            try:
                out.append((m.log_time, decode(m.data, cls)))
            except ProtocolError as exc:  # only valid payloads are on these channels; be tolerant anyway
                refused.append(exc)
    name = schema.removeprefix("foresight.")
    try:
        check_readable(len(out), refused, f"{name} message(s)")
    except UserError as exc:
        raise UserError(f"{lf.path}: {exc}") from None
    if required and refused and not out:
        raise UserError(f"{lf.path}: {len(refused)} {name} message(s), none decodable (first error: {refused[0]})")
    return out


def _latest_before(items: list[tuple[int, Any]], t: int, pred: Callable[[Any], bool] = lambda _: True) -> Any:
    best = None
    for lt, msg in items:
        if lt <= t and pred(msg):
            best = msg
    return best


def step_views(lf: LogFile) -> dict[int, StepView]:
    """One :class:`StepView` per replanning step (``Plan.step``) in the log (the last plan of a step wins).

    Real time: one per plan the executor adopted (:mod:`services.adopted_plans`), numbered by its place among the
    logged plans, as ``foresight log table`` numbers its rows; it listed every plan logged, 0..15 where the table had
    0..10 (a review).
    """
    plans = decode_all(lf, "foresight.Plan", Plan, required=True)
    occs = decode_all(lf, "foresight.OccupancyGrid", OccupancyGrid)
    poses = decode_all(lf, "foresight.HumanPose", HumanPose)
    states = decode_all(lf, "foresight.RobotState", RobotState)
    realtime = bool(plans) and all(p.tick < 0 for _, p in plans)
    t0 = 0.0
    if realtime:
        t0 = min([s.stamp for _, s in states] or [p.stamp for _, p in plans])
    numbered = list(enumerate(plans))
    if realtime and states:
        from services.adopted_plans import adopted

        keep = adopted([lt / 1e9 for lt, _ in plans], [s.stamp for _, s in states])
        numbered = [(k, p) for (k, p), a in zip(numbered, keep, strict=True) if a]
    views: dict[int, StepView] = {}
    for k, (lt, plan) in numbered:
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
        views[k if realtime else plan.step] = StepView(plan, occ, pose, first, _latest_before(states, lt), t0,
                                                       k if realtime else None)
    return views


def scene_of(lf: LogFile) -> Scene:
    """The scene the run used: the log's ``scene.toml`` attachment, else the default scene."""
    text = lf.attachments.get("scene.toml")
    if text is None:
        return load_scene(None)
    try:
        data = tomllib.loads(text.decode())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"{lf.path}: its scene.toml attachment is unreadable ({exc})") from None
    return parse_scene(data, "scene.toml (attached)")


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
    name = f"Replanning step {plan.step}" if view.number is None else f"Plan {view.number}"
    return (f"{name} ({when}): chosen {plan.goal_names[plan.chosen]}; cost {costs}; "
            f"planning {plan.planning_ms:.0f} ms\n{occ_txt}{state_txt}")
