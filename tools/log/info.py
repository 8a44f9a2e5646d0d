"""``foresight log info``: a run's MCAP log in a few lines (or one JSON object).

Header, time range, channels (topic, schema, encodings, message counts), attachments, metadata and
rejected payloads; a file whose writer was killed is read up to its last complete chunk and the
summary says it is truncated. Refused payloads (the ``/foresight/rejected`` channel) are not data:
they are left out of the message count and reported on their own, per key and reason. The ``ran:`` line
(:func:`steps_run`) says how many of the run's steps the log holds: an interrupted run's log is complete too.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from shared.protocol import Keys
from shared.recording.reader import SOURCE_METADATA, STILL_WRITTEN, LogFile
from shared.recording.schemas import REJECTED_TOPIC

__all__ = ["info_dict", "format_info", "steps_run"]


def _fmt_time(ns: int | None) -> str:
    if ns is None:
        return "-"
    return datetime.fromtimestamp(ns / 1e9, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "Z"


def _counts(lf: LogFile, name: str, warnings: list[str]) -> dict[str, int]:
    """A metadata record of counts; entries that are not (another tool's record of that name) are left out, named.

    One such entry made ``info`` refuse the whole file (a review): the rest of the log is still worth showing.
    """
    counts, bad = {}, {}
    for k, v in lf.metadata.get(name, {}).items():
        try:
            counts[k] = int(v)
        except ValueError:
            bad[k] = v
    if bad:
        warnings.append(f"metadata {name!r}: {len(bad)} entr{'y' if len(bad) == 1 else 'ies'} not counts, left out "
                        f"(not a Foresight log, or a damaged one): {_shown(bad)}")
    return counts


def _shown(entries: dict[str, str], limit: int = 200) -> str:
    text = repr(entries)
    return text if len(text) <= limit else text[:limit] + "...}"


def steps_run(lf: LogFile) -> dict[str, Any] | None:
    """How much of its run a log holds, from its channels' counts and times; None where it cannot tell.

    Lock-step: the clock ticks logged (one a step; the steps that finish the last plan send none). Real time: the
    span of the robot's states (the first is a state period into the run; the last at or past its end): the
    executor's ``done after N steps``. A run with ``stop_on_goal`` may end early at its goal: not said interrupted.
    ``foresight log info`` said ``run: mode=realtime steps=20 ... complete`` of a run interrupted after 2 (a review).

    Returns:
        ``steps`` (run), ``of`` (the steps configured; 0: no bound), ``interrupted`` and, in real time, ``more_s``
        (seconds past the run's end it went on to reach its goal: ``finish_s``).
    """
    run = lf.metadata.get("foresight.run", {})
    try:
        mode, of, period = run["mode"], int(run["steps"]), float(run["step_period_s"])
        keys = Keys(run.get("prefix", "foresight"))
    except (KeyError, ValueError):
        return None
    early = run.get("stop_on_goal") == "True"
    if mode == "lockstep":
        n = sum(c.count for c in lf.channels.values() if c.topic == keys.clock)
        return {"steps": n, "of": of, "interrupted": bool(of) and n < of and not early, "more_s": 0.0}
    states = [c for c in lf.channels.values() if c.topic == keys.robot_state and c.first_time is not None]
    if mode != "realtime" or not states or period <= 0:
        return None
    try:
        h = 1.0 / float(run.get("state_rate_hz", "50"))
    except (ValueError, ZeroDivisionError):
        return None
    ran = (max(c.last_time for c in states) - min(c.first_time for c in states)) / 1e9 + h  # the last state's time
    n = int(ran / period + 1e-6)
    end = of * period
    return {"steps": min(n, of) if of else n, "of": of, "interrupted": bool(of) and ran + h < end and not early,
            "more_s": max(0.0, ran - end) if of and ran - end > h else 0.0}


def _ran_line(ran: dict[str, Any]) -> str:
    of = f" of {ran['of']}" if ran["of"] else ""
    more = f", and {ran['more_s']:.1f} s more (finish_s: on until the robot arrives)" if ran["more_s"] else ""
    return f"ran:       {ran['steps']}{of} steps{more}" + (" (interrupted)" if ran["interrupted"] else "")


def info_dict(lf: LogFile) -> dict[str, Any]:
    """The summary :func:`format_info` prints, as a JSON-ready dict."""
    firsts = [c.first_time for c in lf.channels.values() if c.first_time is not None]
    lasts = [c.last_time for c in lf.channels.values() if c.last_time is not None]
    warnings: list[str] = []
    rejects, reasons = _counts(lf, "foresight.rejects", warnings), _counts(lf, "foresight.rejects.reasons", warnings)
    refused = sum(c.count for c in lf.channels.values() if c.topic == REJECTED_TOPIC)
    return {
        "path": lf.path, "size_bytes": lf.size, "complete": lf.complete, "error": lf.error,
        "being_written": lf.being_written, "damage": lf.damage, "chunks_skipped": lf.chunks_skipped,
        "messages_lost": lf.messages_lost,
        "profile": lf.profile, "library": lf.library,
        "start": _fmt_time(min(firsts)) if firsts else None, "end": _fmt_time(max(lasts)) if lasts else None,
        "duration_s": (max(lasts) - min(firsts)) / 1e9 if firsts else 0.0,
        "messages": lf.message_count - refused,
        "rejected_records": refused,
        "channels": [{"topic": c.topic, "schema": c.schema_name, "schema_encoding": c.schema_encoding,
                      "message_encoding": c.message_encoding, "messages": c.count}
                     for c in sorted(lf.channels.values(), key=lambda c: c.topic)],
        "attachments": {k: len(v) for k, v in lf.attachments.items()},
        "metadata": lf.metadata,
        "rejected": rejects,
        "rejected_reasons": reasons,
        "warnings": warnings,
        "ran": steps_run(lf),
    }


def _state_words(lf: LogFile, d: dict) -> str:
    """The file line's account of the log's state (``d``: :func:`info_dict`)."""
    source = lf.metadata.get(SOURCE_METADATA, {})  # a whole copy of a log that was not
    if lf.complete and source.get("source_error") == STILL_WRITTEN:
        return ("complete; copied from a log still being written, up to its last whole chunk then: what the run wrote "
                "after that is not here")
    if lf.complete and source.get("source_state") == "DAMAGED":  # not truncated: nothing was cut (a review)
        return (f"complete; copied from a DAMAGED log ({source.get('source_error', '')}): what the damage took is not "
                "here")
    if lf.complete and source.get("source_complete") == "false":
        return (f"complete; copied from a TRUNCATED log ({source.get('source_error', 'no footer')}): what the run "
                "wrote after its last whole chunk is not here")
    if lf.complete:
        return "complete"
    if lf.summary_damaged:
        return f"{lf.state}: all {d['messages']} messages read in file order; its index is not to be trusted"
    if lf.damage:
        return f"{lf.state}: {d['messages']} messages read, {d['duration_s']:.2f} s"
    if lf.being_written:  # not a killed run's end: the run goes on
        return f"{lf.state}: {d['messages']} messages, {d['duration_s']:.2f} s"
    return (f"{lf.state}: recovered {d['messages']} messages"
            + (f" and {d['rejected_records']} refused payloads" if d["rejected_records"] else "")
            + f", {d['duration_s']:.2f} s, up to the last whole chunk")


def format_info(lf: LogFile) -> str:
    """Human-readable summary: file state, time range, one line per channel, attachments, metadata."""
    d = info_dict(lf)
    state = _state_words(lf, d)
    lines = [f"file:      {lf.path} ({lf.size / 1e6:.2f} MB, {state})",
             f"profile:   {lf.profile or '-'}   library: {lf.library or '-'}",
             f"time:      {d['start']} .. {d['end']} ({d['duration_s']:.2f} s)" if d["start"] else "time:      -",
             f"messages:  {d['messages']} on {len(lf.channels) - (d['rejected_records'] > 0)} channels"
             + (f" (and {d['rejected_records']} refused payloads on {REJECTED_TOPIC}, not counted)"
                if d["rejected_records"] else ""), ""]
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
        if d["ran"] is not None:
            lines.append(_ran_line(d["ran"]))
    if "foresight.rejects" in lf.metadata:
        rej = d["rejected"]
        lines += ["rejected:  " + (", ".join(f"{k}: {v}" for k, v in sorted(rej.items())) if rej else "none")]
        if d["rejected_reasons"]:
            lines += ["  by reason: " + ", ".join(f"{k}: {v}" for k, v in sorted(d["rejected_reasons"].items()))]
    elif not lf.complete:
        lines += ["rejected:  (counts are written when the file is closed)"]
    viz = lf.metadata.get("foresight.viz")
    if viz:  # the scene updates: dropped when the executor's background thread fell behind (real time)
        lines += ["foxglove:  " + ", ".join(f"{k} {v}" for k, v in viz.items()) + " (updates; the raw messages are all "
                  "there)"]
    lines += [f"warning:   {w}" for w in d["warnings"]]
    return "\n".join(lines)
