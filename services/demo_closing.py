"""What ``foresight demo`` prints at its end: the summary (or the comparison), its picture, where its files are."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from services.demo_dirs import describe_log

if TYPE_CHECKING:
    from services.demo import DemoConfig
    from services.scenario import Summary

__all__ = ["closing_lines", "picture"]


def picture(draw: Callable[[Path], Path], png: Path, out: Callable[[str], None]) -> Path | None:
    """``draw(png)``; a failure to write it (a full disk) is one warning: the run's outcome is printed regardless."""
    try:
        return draw(png)
    except OSError as exc:
        png.unlink(missing_ok=True)
        out(f"foresight demo: warning: the picture of the run was not drawn: {exc.filename or png}: "
            f"{exc.strerror or exc}")
        return None


def closing_lines(cfg: DemoConfig, summary: Summary, interrupted: bool = False) -> list[str]:
    """What the demo prints at the end: the run's summary (or the comparison), the picture, where everything is.

    ``interrupted``: the MCAP lines say each log's state (``complete``: finalised); else only a log not complete.
    """
    extra, robot = summary.extra, "the prediction planner's robot" if cfg.compare else "the robot"  # summary: its run
    lines = [] if cfg.compare else summary.lines(table=False)[:-1]  # the table was printed live; the log comes last
    if cfg.mode == "realtime" and not summary.reached and "cut_short" not in extra and summary.separation_at_end:
        lines.append(f"note: {robot} had not arrived: the separation guard held it at the end "
                     f"({summary.separation_held_s:.1f} s of the run in all), its path passing nearer the person than "
                     "separation.stop_m (docs/executor.md: it waits for the person to step back; --config with "
                     "[executor.separation] stop_m = 0 turns it off)")
    elif cfg.mode == "realtime" and not summary.reached and "cut_short" not in extra:
        lines.append(f"note: a real-time run lasts its {cfg.steps} steps of {cfg.period_s:g} s ({cfg.run_s:g} s)"
                     + (f" and goes on until the robot arrives, at most {cfg.finish_s:g} s more" if cfg.finish else "")
                     + f"; {robot}, at {cfg.robot_speed:g} of its velocity limits, had not arrived: "
                     + (f"--steps {2 * cfg.steps} gives it twice as long" if cfg.finish else
                        "--finish lets it go on to its goal"))
    elif (cfg.mode == "realtime" and cfg.finish and summary.reached and summary.reached_t_s is not None
          and summary.reached_t_s > cfg.run_s):
        lines.append(f"note: {robot} arrived {summary.reached_t_s - cfg.run_s:.1f} s after the run's {cfg.run_s:g} "
                     f"s: the run goes on until it is there (--no-finish ends it at {cfg.run_s:g} s)")
    lines += extra.get("outcome_lines", [])

    def with_state(path: str | None) -> str:  # its state after an interrupt, else only when it is not complete
        return describe_log(path, interrupted, extra.get("log_incomplete", "") if path == summary.mcap_path else "")

    if cfg.compare:
        lines.append("MCAP logs: " + ", ".join(with_state(r["mcap_path"]) for r in extra.get("comparison", [])))
    else:
        lines.append(f"MCAP log: {with_state(summary.mcap_path)}")
    if "figure" in extra:
        lines.append(f"picture of the run: {extra['figure']}")
    each = "plan" if cfg.mode == "realtime" else "step"  # render numbers a real-time run's plans, not its steps
    lines.append(f"this run's logs: {extra.get('run_dir')}/ (each {each}: foresight log render "
                 f"{summary.mcap_path} --step N --out {each}.png)")
    return lines
