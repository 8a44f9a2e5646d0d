"""Keypoint libraries: recorded demonstrations as 3D body points, one CSV per class, to and from motion libraries.

A keypoint library is a directory with one ``<class>.csv`` per class; header
``demo,frame,<point>_x,<point>_y,<point>_z,...`` (metres, the recorder's frame), one row per frame,
demonstrations one after another; a missing point is an absent column or an empty cell, a dropped frame an
absent row. Points are named as a layout names them (:mod:`shared.keypoints.layouts`; Foresight's own names
by default). :func:`write_keypoint_library` makes one from a motion library (the human model's joint
positions, optionally with noise, dropped frames and missing points); :func:`fit_keypoint_library` turns one
into a motion library (:class:`shared.keypoints.KeypointFit`, frame by frame, gaps and a sensor's glitches bridged by
interpolating the fitted features).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shared.atomic_file import atomic_write, make_parent
from shared.feature_sets import require_mapping
from shared.human import HumanModel
from shared.library import Demonstration, LibraryIssue, MotionLibrary

from .fit import POINT_NAMES, REQUIRED, FitConfig, KeypointFit
from .layouts import load_layout
from .plausibility import MAX_KEYPOINT_M, far_frames, recording_problem

__all__ = ["write_keypoint_library", "read_keypoint_csv", "fit_keypoint_library", "KeypointDemo", "FitReport",
           "CLASS_ORDER_FILE"]


@dataclass
class KeypointDemo:
    """One demonstration of a keypoint CSV: its frame numbers and points (layout names)."""

    demo: int
    frames: np.ndarray     # (T,) int
    names: list[str]       # K
    positions: np.ndarray  # (T, K, 3), NaN where missing


@dataclass
class FitReport:
    """What :func:`fit_keypoint_library` measured: every observed point's fit residual, frames bridged and refused."""

    residual_m: np.ndarray  # (N,) over every observed point of every frame taken
    frames: int             # frames taken
    bridged: int            # frames interpolated: absent, a required point missing, or refused
    refused: int = 0        # of them, a sensor's glitches: a coordinate beyond MAX_KEYPOINT_M, or a fit over the limit
    max_residual_m: float = 0.08

    def line(self) -> str:
        """One line: median and p99 residual, frames fitted, bridged and refused."""
        r = self.residual_m
        return (f"fit residual median {np.median(r) * 1e3:.2f} mm, p99 {np.percentile(r, 99) * 1e3:.2f} mm over "
                f"{len(r)} points of {self.frames} frames; {self.bridged} frames bridged (dropped, a required "
                f"point missing, or refused: {self.refused} with a coordinate beyond {MAX_KEYPOINT_M:g} m or a fit "
                f"residual over {self.max_residual_m * 100:g} cm rms, a sensor's glitches)")


def write_keypoint_library(lib: MotionLibrary, out: Path, noise_m: float = 0.0, drop: float = 0.0,
                           missing: float = 0.0, seed: int = 0) -> list[Path]:
    """Write ``lib`` as a keypoint library: the human model's joint positions of every sample.

    Args:
        lib: A motion library of the paper's 12 features.
        out: The directory (created).
        noise_m: Standard deviation of Gaussian noise per axis, metres.
        drop: Fraction of frames left out (never a demonstration's first).
        missing: Fraction of frames with one point (chosen at random) left empty.
        seed: Seed of the noise, drops and missing points.

    Returns:
        The CSV files written (and :data:`CLASS_ORDER_FILE`, the classes' order). Any other ``*.csv`` in ``out``
        (an earlier library's classes) is removed: the reader takes every one, and would mix the two libraries.

    Raises:
        ValueError: The library's features have no mapping to the human model (checked before anything is
            written), or ``noise_m`` is not finite.
    """
    mapping = require_mapping(lib.feature_names, "a keypoint library (the human model's joint positions)",
                    f"library {lib.source}")
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise ValueError(f"noise_m: must be a finite number >= 0, got {noise_m}")
    rng = np.random.default_rng(seed)
    model = HumanModel()
    make_parent(out / "x.csv")
    header = ["demo", "frame", *(f"{p}_{a}" for p in POINT_NAMES for a in "xyz")]
    written = []
    for label, name in enumerate(lib.class_names):
        path = out / f"{name}.csv"
        text = io.StringIO(newline="")
        w = csv.writer(text)
        w.writerow(header)
        for demo in (d for d in lib.demos if d.label == label):
            pts = model.joint_positions(mapping.to_human(demo.features))  # (T, J, 3)
            pts = pts + rng.normal(0.0, noise_m, pts.shape) if noise_m > 0 else pts
            keep = rng.random(len(pts)) >= drop
            keep[0] = True
            blank = rng.random(len(pts)) < missing
            which = rng.integers(0, len(POINT_NAMES), len(pts))
            for t in np.flatnonzero(keep):
                row = [f"{v:.5f}" for v in pts[t].reshape(-1)]
                if blank[t]:
                    row[3 * which[t]:3 * which[t] + 3] = ["", "", ""]
                w.writerow([demo.index, t, *row])
        with atomic_write(path) as f:  # whole or not at all: Ctrl-C mid-class left the old CSV cut short
            f.write(text.getvalue().encode("utf-8"))
        written.append(path)
    for stale in set(out.glob("*.csv")) - set(written):
        stale.unlink()
    with atomic_write(out / CLASS_ORDER_FILE) as f:  # the labels' order: sorted names would reorder the classes
        f.write("".join(f"{name}\n" for name in lib.class_names).encode())
    return written


def read_keypoint_csv(path: Path) -> list[KeypointDemo]:
    """The demonstrations of one keypoint CSV.

    Raises:
        ValueError: A header without ``demo,frame`` and ``<point>_x/_y/_z`` triplets, a cell that is not a number,
            a point with some of its three cells empty, frames not increasing within a demonstration (the message
            names the file and line).
    """
    with path.open(newline="", encoding="utf-8-sig") as f:  # a byte-order mark is no part of the header
        rows = [row for row in csv.reader(f) if any(cell.strip() for cell in row)]  # blank lines: nothing
    if not rows or rows[0][:2] != ["demo", "frame"] or (len(rows[0]) - 2) % 3:
        raise ValueError(f"{path}: header must be demo,frame,<point>_x,<point>_y,<point>_z,... (got "
                         f"{','.join(rows[0][:5]) if rows else 'an empty file'})")
    cols = rows[0][2:]
    names = [c[:-2] for c in cols[::3]]
    if any(cols[3 * i:3 * i + 3] != [f"{n}_x", f"{n}_y", f"{n}_z"] for i, n in enumerate(names)):
        raise ValueError(f"{path}: columns must come as <point>_x,<point>_y,<point>_z triplets")
    if twice := sorted({n for n in names if names.count(n) > 1}):  # the last would silently stand for both
        raise ValueError(f"{path}: point(s) {', '.join(twice)} given twice in the header")
    by_demo: dict[int, list[tuple[int, list[float]]]] = {}
    last_demo: int | None = None
    for line, row in enumerate(rows[1:], start=2):
        try:
            demo, frame = int(row[0]), int(row[1])
            values = [float(v) if v.strip() else np.nan for v in row[2:]]
        except (ValueError, IndexError) as exc:
            raise ValueError(f"{path}:{line}: {exc}") from None
        if any(np.isinf(values)):  # a missing point is an empty cell; infinity is a sensor's or a writer's bug
            raise ValueError(f"{path}:{line}: a coordinate is infinite")
        if len(values) != len(cols):
            raise ValueError(f"{path}:{line}: {len(values)} values, the header has {len(cols)}")
        if partly := [n for i, n in enumerate(names) if 0 < np.isnan(values[3 * i:3 * i + 3]).sum() < 3]:
            raise ValueError(f"{path}:{line}: point(s) {', '.join(partly)} partly empty (a point not seen has all "
                             "three cells empty)")  # else read as not seen by one command and refused by another
        if demo in by_demo and demo != last_demo:
            raise ValueError(f"{path}:{line}: demo {demo} again after demo {last_demo} (a demonstration's rows "
                             "come together)")
        last_demo = demo
        frames = by_demo.setdefault(demo, [])
        if frames and frame <= frames[-1][0]:
            raise ValueError(f"{path}:{line}: frame {frame} of demo {demo} after frame {frames[-1][0]}")
        frames.append((frame, values))
    return [KeypointDemo(d, np.array([f for f, _ in fr]), names,
                         np.array([v for _, v in fr], dtype=np.float64).reshape(len(fr), len(names), 3))
            for d, fr in by_demo.items()]


CLASS_ORDER_FILE = "classes.txt"
"""A keypoint library's class order, one class name a line (``to-keypoints`` writes it; without it: sorted)."""


def _class_files(directory: Path) -> list[Path]:
    """The library's ``<class>.csv`` files in its class order (:data:`CLASS_ORDER_FILE`, else sorted by name).

    Raises:
        ValueError: No CSV, or an order file whose names are not exactly the CSVs' classes.
    """
    files = sorted(directory.glob("*.csv"))
    if not files:
        raise ValueError(f"keypoint library {directory}: no <class>.csv files")
    order = directory / CLASS_ORDER_FILE
    if not order.is_file():
        return files
    names = [n.strip() for n in order.read_text(encoding="utf-8").splitlines() if n.strip()]
    stems = {p.stem for p in files}
    if len(set(names)) != len(names) or set(names) != stems:
        raise ValueError(f"{order}: lists {', '.join(names) or 'nothing'}, but the CSV files are "
                         f"{', '.join(sorted(stems))} (one name a line, each CSV once)")
    return [directory / f"{n}.csv" for n in names]


def fit_keypoint_library(directory: Path, layout: str = "foresight", config: FitConfig | None = None,
                         max_residual_m: float = 0.08) -> tuple[MotionLibrary, FitReport]:
    """Fit the 12 features to every demonstration of a keypoint library; returns the motion library and a report.

    Frames are fitted in order, each warm-started from the last one taken (all demonstrations at once), as the live
    tracker fits them. Frames that are absent, lack a required point, hold a coordinate beyond
    :data:`~shared.protocol.limits.MAX_KEYPOINT_M` (the wire refuses such a live frame) or whose fit's rms residual
    exceeds ``max_residual_m`` (the live tracker's limit per frame) get the features interpolated between their
    neighbours: such a frame is a sensor's glitch, and never the next frame's start
    (:meth:`~shared.keypoints.KeypointFit.fit_sequences`). A demonstration whose median fit residual exceeds
    ``max_residual_m``, or without a frame within it, is left out as a :class:`~shared.library.LibraryIssue` of the
    library: its points do not fit the model.

    Raises:
        ValueError: No CSV in ``directory``, a malformed one, a demonstration that is not in metres, whose up is
            not z, or without a frame with every required point
            (:func:`~shared.keypoints.plausibility.recording_problem`), or a class left with none.
    """
    files = _class_files(Path(directory))
    lay = load_layout(layout)
    demos: list[tuple[int, str, KeypointDemo, np.ndarray]] = []
    for label, path in enumerate(files):
        for kd in read_keypoint_csv(path):
            if unknown := lay.unknown(kd.names):  # a typo would be a point never observed, without a word
                raise ValueError(f"{path}: point(s) {', '.join(unknown)} are not layout {lay.name}'s")
            if problem := recording_problem(lay, kd.names, kd.positions):  # as tracker --from refuses to play it
                raise ValueError(f"{path} demo {kd.demo}: {problem}")
            demos.append((label, path.stem, kd, lay.to_model(kd.names, kd.positions)))
    if not demos:
        raise ValueError(f"keypoint library {directory}: no demonstration in any of its {len(files)} CSV files")
    required = [POINT_NAMES.index(p) for p in REQUIRED]
    given = [np.all(np.isfinite(pts[:, required]).all(-1), axis=-1) for *_, pts in demos]
    far = [g & far_frames(kd.positions) for (_, _, kd, _), g in zip(demos, given, strict=True)]
    usable = [g & ~w for g, w in zip(given, far, strict=True)]
    longest = max(int(u.sum()) for u in usable)
    batch = np.zeros((len(demos), max(longest, 1), len(POINT_NAMES), 3))
    for i, ((*_, pts), ok) in enumerate(zip(demos, usable, strict=True)):
        kept = pts[ok] if ok.any() else pts[given[i]][:1]  # every frame far off: fitted, not taken (below)
        batch[i, :len(kept)] = kept
        batch[i, len(kept):] = kept[-1]  # padding: the last frame again (its fits are not used)
    result = KeypointFit(config).fit_sequences(batch, max_residual_m=max_residual_m)
    assert result.refused is not None
    out, residuals, bridged, fitted, refused = [], [], 0, 0, 0
    issues: list[LibraryIssue] = []
    counts: dict[int, int] = {}
    for i, ((label, name, kd, _), ok) in enumerate(zip(demos, usable, strict=True)):
        n = int(ok.sum())
        taken = ~result.refused[i, :n]
        r = result.residual_m[i, :n]
        rms = np.sqrt(np.nanmean(r ** 2, axis=-1))
        r = r[np.isfinite(r)]
        if r.size and float(np.median(r)) > max_residual_m:
            issues.append(LibraryIssue(name, kd.demo, f"demo {kd.demo}: fit residual median {np.median(r) * 100:.1f} "
                                       f"cm > {max_residual_m * 100:g} cm: its points do not fit the model (another "
                                       "layout? --layout)"))
            continue
        if not taken.any():
            why = (f"a coordinate beyond {MAX_KEYPOINT_M:g} m in every frame with the required points" if not n else
                   f"no frame fits the model within {max_residual_m * 100:g} cm rms (best: {rms.min() * 100:.1f} cm)")
            issues.append(LibraryIssue(name, kd.demo, f"demo {kd.demo}: {why}"))
            continue
        frames = kd.frames[ok][taken]
        span = np.arange(kd.frames[0], kd.frames[-1] + 1)
        feats = np.stack([np.interp(span, frames, result.features[i, :n][taken, k]) for k in range(12)], axis=-1)
        bridged += len(span) - len(frames)
        refused += int(far[i].sum()) + int((~taken).sum())
        fitted += len(frames)
        kept_r = result.residual_m[i, :n][taken]
        residuals.append(kept_r[np.isfinite(kept_r)])
        index = counts[label] = counts.get(label, -1) + 1
        out.append(Demonstration(label, name, index, feats, f"{name}.csv#demo {kd.demo}"))
    given_labels = {label for label, *_ in demos}
    empty = [f"{p.stem} ({'none fits the model' if label in given_labels else 'none given'})"
             for label, p in enumerate(files) if label not in counts]
    if empty:  # training would refuse the library, far from here
        raise ValueError(f"keypoint library {directory}: no demonstration of {', '.join(empty)}"
                         + (f"; {'; '.join(map(str, issues[:3]))}" if issues else ""))
    lib = MotionLibrary([p.stem for p in files], out, issues, f"keypoints:{directory} (layout {lay.name})")
    return lib, FitReport(np.concatenate(residuals), fitted, bridged, refused, max_residual_m)
