"""``foresight eval pace``: at what robot pace, relative to the human, does prediction pay off.

Table I (:mod:`services.experiments.interference`: basic STOMP against least penetration, the same held-out
demonstrations and seeds) repeated across the robot's pace, for each protocol and library. The pace is each
protocol's own: ``product``, the fraction of the PR2's velocity limits its trajectories are timed at
(0.5 s per step); ``paper``, the configuration-space length executed per step (the authors': 0.05 in the
side scene). From "arrives before the reach is recognised" to "arrives after the human has finished": the
reached step says which, per point. Per point: Table I's ratio, and per planner the real human's contact
time and minimum clearance and the step the robot reaches its goal (median over the runs).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .heldout import short_name
from .interference import InterferenceConfig, InterferenceResult, ratio_text, run_interference
from .planners import Timing
from .protocol import DEFAULT_PACES, PAPER, protocol

__all__ = ["PaceConfig", "PacePoint", "PaceResult", "run_pace", "plot_pace", "DEFAULT_PACES", "OPERATING_POINT"]


OPERATING_POINT = {"product": Timing.robot_speed, "paper": PAPER.pace(PAPER.table1_scene)}
"""Each protocol's own pace: the product's default speed and the authors' side-scene pace."""

PLANNERS = ("basic", "least_penetration")


@dataclass(frozen=True)
class PaceConfig:
    """Options of the pace sweep."""

    libraries: tuple[str, ...] = ("synthetic",)
    protocols: tuple[str, ...] = ("product", "paper")
    paces: dict[str, tuple[float, ...]] = field(default_factory=lambda: dict(DEFAULT_PACES))
    demos: int = 5
    draw: int = InterferenceConfig.demos  # the demonstrations: the first ``demos`` of Table I's draw of this many
    seeds: int = 2
    timing: Timing = Timing()
    components: int | None = None
    volume: str | None = None  # the product protocol's occupancy volume (None: the trainer's); the paper's: its own
    models_dir: Path = Path("models/experiments")
    work_dir: Path = Path("runs/experiments")


@dataclass(frozen=True)
class PacePoint:
    """One protocol, library and pace: Table I's ratio and, per planner, the real human and the reached step."""

    protocol: str
    library: str
    pace: float
    ratio: float
    planners: dict[str, dict[str, float | None]]

    def to_json(self) -> dict[str, Any]:
        """The point as JSON: ``protocol``, ``library``, ``pace``, ``ratio``; per planner ``contact_s``, etc."""
        return {"protocol": self.protocol, "library": self.library, "pace": self.pace, "ratio": self.ratio,
                **self.planners}


def _point(res: InterferenceResult, prot: str, library: str, pace: float) -> PacePoint:
    out: dict[str, dict[str, float | None]] = {}
    for name in PLANNERS:
        runs = [r for r in res.runs if r.planner == name]
        reached = [r.reached_step for r in runs if r.reached_step is not None]
        out[name] = {"contact_s": float(np.mean([r.time_in_contact for r in runs])),
                     "min_clearance_m": float(np.median([r.min_clearance for r in runs])),
                     "reached_step": float(np.median(reached)) if len(reached) == len(runs) else None,
                     "interference": float(np.mean([r.interference for r in runs]))}
    return PacePoint(prot, short_name(library), pace, res.ratio(), out)


@dataclass
class PaceResult:
    """Every point of the sweep."""

    config: PaceConfig
    points: list[PacePoint] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """``points``: one object per protocol, library and pace; ``operating_point`` per protocol; ``verdicts``."""
        verdicts = {f"{prot}, {lib}": self.verdict(prot, lib) for prot in self.config.protocols
                    for lib in sorted({p.library for p in self.points})}
        return {"points": [p.to_json() for p in self.points], "operating_point": OPERATING_POINT, "verdicts": verdicts,
                "demos": self.config.demos, "seeds": self.config.seeds}

    def pays(self, prot: str, library: str) -> list[tuple[float, bool | None]]:
        """Per pace (slowest first): whether least penetration touched the real human less than basic STOMP.

        None where neither touched it (nothing to lower).
        """
        pts = sorted((p for p in self.points if p.protocol == prot and p.library == library), key=lambda p: p.pace)
        out: list[tuple[float, bool | None]] = []
        for p in pts:
            b, lp = p.planners["basic"]["contact_s"], p.planners["least_penetration"]["contact_s"]
            out.append((p.pace, None if b <= 1e-9 and lp <= 1e-9 else lp < b - 1e-9))
        return out

    def verdict(self, prot: str, library: str) -> str:
        """Where least penetration stops lowering the contact with the real human, and where it touches longer."""
        pays = self.pays(prot, library)
        lower = [p for p, ok in pays if ok]
        longer = [p.pace for p in self.points if p.protocol == prot and p.library == library
                  and p.planners["least_penetration"]["contact_s"] > p.planners["basic"]["contact_s"] + 1e-9]
        if not lower:
            n, k = self.config.demos, self.config.seeds  # a sample: Table I's 5 x 10 runs touched where 3 x 1 did not
            what = (f"neither planner touches the human at any pace in these {n} x {k} runs per pace"
                    if all(ok is None for _, ok in pays) else "least penetration lowers the contact at no pace")
        else:
            faster = [p for p, _ in pays if p > max(lower)]
            what = (f"least penetration lowers the contact at pace {', '.join(f'{p:g}' for p in lower)}; "
                    + (f"from pace {min(faster):g} on it no longer does" if faster else
                       "it still does at the fastest pace swept"))
        return f"{what}; touches longer than basic STOMP at {', '.join(f'{p:g}' for p in longer) or 'no pace'}"

    def lines(self) -> list[str]:
        """One row per point, then per protocol and library where prediction stops lowering contact."""
        demos, seeds = self.config.demos, self.config.seeds
        out = [f"Table I across the robot's pace ({demos} demonstration{'s' * (demos != 1)} x {seeds} "
               f"seed{'s' * (seeds != 1)}); "
               "contact s (mean) / min clearance m (median) / reached step (median; - : not every run)",
               f"{'protocol':<9}{'library':<16}{'pace':>8}{'ratio':>12}{'basic':>28}{'least penetration':>28}"]
        for p in self.points:
            cells = []
            for name in PLANNERS:
                c = p.planners[name]
                r = "-" if c["reached_step"] is None else f"{c['reached_step']:.0f}"
                cells.append(f"{c['contact_s']:6.2f} / {c['min_clearance_m']:+.3f} / {r:>3}")
            row = f"{p.protocol:<9}{p.library:<16}{p.pace:>8.4g}{ratio_text(p.ratio):>12}"
            out.append(row + "".join(f"{x:>28}" for x in cells))
        for prot in self.config.protocols:
            for lib in sorted({p.library for p in self.points}):
                out.append(f"{prot}, {lib}: {self.verdict(prot, lib)}")
        return out


def run_pace(cfg: PaceConfig, progress: Callable[[str], None] = print, compile: bool = True) -> PaceResult:
    """Run Table I at every pace of every protocol and library."""
    result = PaceResult(cfg)
    said: set[str] = set()

    def relay(line: str) -> None:
        # each run's line and what the runs say, indented under the point's; not the setup line (the point's says
        # where), and a warning once (each pace's Table I repeats its class's; it was dropped with the setup line)
        if line.startswith("interference (") or line in said:
            return
        if line.startswith("warning:"):
            said.add(line)
        progress(f"  {line}")

    for prot in cfg.protocols:
        protocol(prot)  # raises on a bad name
        for library in cfg.libraries:
            for pace in cfg.paces[prot]:
                if not (pace > 0 and math.isfinite(pace)):
                    raise ValueError(f"pace: paces must be > 0, got {pace}")
                timing = dataclasses.replace(cfg.timing, robot_speed=min(1.0, pace)) if prot == "product" \
                    else cfg.timing
                icfg = InterferenceConfig(library=library, scene=protocol(prot).table1_scene, demos=cfg.demos,
                                          draw=cfg.draw, seeds=cfg.seeds, timing=timing,
                                          components=cfg.components, variants=PLANNERS, protocol=prot,
                                          volume=cfg.volume if prot == "product" else None,
                                          path_per_step=pace if prot == "paper" else None,
                                          models_dir=cfg.models_dir, work_dir=cfg.work_dir)
                progress(f"pace: {prot} protocol, {short_name(library)}, pace {pace:g}")
                res = run_interference(icfg, progress=relay, compile=compile)
                result.points.append(_point(res, prot, library, pace))
                progress(f"  ratio {ratio_text(res.ratio())}")
    return result


def plot_pace(res: PaceResult, path: Path) -> Path:
    """Ratio, contact and reached step against the pace: one column per protocol, one colour per library.

    Each library keeps its colour in every row (basic STOMP dashed, least penetration solid): the ratio row's orange
    was the synthetic library, the rows below's the paper's least penetration. The ticks are the paces run (a log
    axis over a small range wrote its labels over each other), and a ratio the log axis cannot show (0 or inf) is
    named on the axes rather than dropped.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    protocols = list(res.config.protocols)
    fig, axes = plt.subplots(3, len(protocols), figsize=(5.5 * len(protocols), 9), squeeze=False, sharex="col")
    units = {"product": "robot speed (fraction of the PR2's velocity limits)",
             "paper": "path length per step (configuration space)"}
    libraries = sorted({p.library for p in res.points})
    for col, prot in enumerate(protocols):
        loggable = False  # a ratio the log axis can show (a sweep of ratios 0 or inf only crashed the plot)
        off: list[str] = []
        for i, lib in enumerate(libraries):
            colour = f"C{i}"
            pts = sorted((p for p in res.points if p.protocol == prot and p.library == lib), key=lambda p: p.pace)
            x = [p.pace for p in pts]
            ratios = [p.ratio if 0 < p.ratio < math.inf else np.nan for p in pts]
            axes[0, col].plot(x, ratios, "o-", color=colour, label=lib)  # 0 (basic never touched) or inf: named
            off += [f"{lib} {p.pace:g}: {ratio_text(p.ratio)}" for p in pts if not 0 < p.ratio < math.inf]
            loggable |= any(r > 0 for r in ratios if not np.isnan(r))
            for name, style in (("basic", "--"), ("least_penetration", "-")):
                label = f"{lib}, {name.replace('_', ' ')}"
                axes[1, col].plot(x, [p.planners[name]["contact_s"] for p in pts], "o" + style, color=colour,
                                  label=label)
                axes[2, col].plot(x, [np.nan if p.planners[name]["reached_step"] is None
                                      else p.planners[name]["reached_step"] for p in pts], "o" + style,
                                  color=colour, label=label)
        paces = sorted({p.pace for p in res.points if p.protocol == prot})
        for row, ylabel in enumerate(("basic / least penetration (Table I)", "contact with the real human (s)",
                                      "step the goal is reached (median)")):
            ax = axes[row, col]
            ax.set_xscale("log")
            ax.axvline(OPERATING_POINT[prot], color="gray", ls=":",
                       label="the authors' pace" if prot == "paper" else "the product's default")
            if paces:
                ax.set_xticks(paces, [f"{p:g}" for p in paces])
                ax.xaxis.set_minor_formatter(NullFormatter())
                lo, hi = min(*paces, OPERATING_POINT[prot]), max(*paces, OPERATING_POINT[prot])
                if hi < 1.5 * lo:  # one pace (--quick) at the operating point: the log axis shrank to nothing
                    ax.set_xlim(lo / 2, hi * 2)  # and its point was drawn nowhere (a review)
            ax.set_ylabel(ylabel)
            ax.legend(fontsize=7)
        if loggable:
            axes[0, col].set_yscale("log")
        if off:
            axes[0, col].text(0.02, 0.02, "not on the log axis: " + "; ".join(off), fontsize=7, wrap=True,
                              transform=axes[0, col].transAxes)
        axes[0, col].set_title(f"{prot} protocol")
        axes[-1, col].set_xlabel(units[prot])
    from .plots import save_figure

    return save_figure(fig, path)
