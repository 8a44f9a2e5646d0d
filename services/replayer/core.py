"""The replayer's pure logic: which demonstrations to stream, and the ordered messages of each step.

No Zenoh here. :class:`ReplayerCore` turns a list of demonstrations into a deterministic stream of
:class:`~shared.protocol.DemoMarker` and :class:`~shared.protocol.HumanPose` messages; the service
asks it for one step at a time (one pose per period in real time, ``samples_per_tick`` poses per
clock tick in lock-step).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shared.config import LOG_LEVELS, ConfigError, opt
from shared.config_names import check_services
from shared.feature_sets import LIVE_MAPPING, require_mapping
from shared.library import Demonstration, MotionLibrary, heldout_split, load_library
from shared.protocol import SERVICES, DemoMarker, HumanPose, Message
from shared.scene import SCENE_HELP, load_scene

__all__ = ["ReplayerConfig", "ReplayEvent", "ReplayerCore", "select_demos", "load_replay_library", "unused_options"]

PEERS = tuple(s for s in SERVICES if s != "replayer")
"""The services ``wait_for`` and ``stop_with`` may name (the wire contract's, but itself)."""
MIN_RATE_HZ, MAX_RATE_HZ = 0.01, 10_000.0
"""``rate_hz``'s range: a pose at least every 100 s (a slower rate overflowed the stream's wait), at most 10 kHz."""


@dataclasses.dataclass
class ReplayerConfig:
    """Options of the replayer (``[replayer]`` in the TOML file)."""

    library: Path | None = opt(None, help="motion library: a directory of compound_*.csv or a .npz; "
                                    "unset = the embedded synthetic library (shared.synthetic, seed 0: the one "
                                    "`foresight train` trains on by default, for --scene)")
    scene: str = opt("", help=SCENE_HELP + " whose cups the embedded synthetic library reaches for, as `foresight "
                              "train --scene` (empty: pr2_two_cups); a --library is streamed as it is")
    mode: str = opt("realtime", choices=("realtime", "lockstep"),
                    help="realtime: publish at --rate-hz; lockstep: publish --samples-per-tick poses per ClockTick")
    rate_hz: float = opt(30.0, help="real-time publishing rate (poses per second)")
    samples_per_tick: int = opt(1, help="lock-step: poses published per clock tick")
    classes: list[int] = opt(default_factory=list, help="stream only these class labels (comma-separated; "
                                                        "empty = all)")
    indices: list[int] = opt(default_factory=list, help="stream only these demonstration indices within each "
                                                        "class (comma-separated; empty = all)")
    heldout: int = opt(0, help="stream only a held-out random set of N demonstrations per class (chosen by --seed "
                               "like shared.library.heldout_split; 0 = no held-out selection)")
    seed: int = opt(0, help="seed of the held-out selection and the shuffle (>= 0)")
    shuffle: bool = opt(False, help="stream the selected demonstrations in a seeded random order")
    loop: bool = opt(False, help="start over after the last demonstration (until stopped)")
    max_demos: int = opt(0, help="stop after this many demonstrations (0 = no limit)")
    wait_for: list[str] = opt(default_factory=list, help="real-time: wait for the liveliness tokens of these "
                                                         "services (e.g. predictor) before streaming")
    wait_timeout: float = opt(300.0, help="seconds to wait for --wait-for services before streaming anyway")
    stop_with: list[str] = opt(default_factory=list, help="end when one of these services (e.g. executor) "
                               "disappears after it was seen (comma-separated; how a compose run ends)")
    log_level: str = opt("INFO", choices=LOG_LEVELS, help="log level")

    def validate(self) -> None:
        """Check value ranges."""
        if not MIN_RATE_HZ <= self.rate_hz <= MAX_RATE_HZ:
            raise ConfigError(f"replayer.rate_hz: must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}], got {self.rate_hz}")
        if self.seed < 0:
            raise ConfigError(f"replayer.seed: must be >= 0, got {self.seed}")
        for name in ("wait_for", "stop_with"):
            check_services(getattr(self, name), f"replayer.{name}", PEERS)
        if self.mode == "lockstep" and self.wait_for:  # it was taken and ignored without a word
            raise ConfigError(f"replayer.wait_for: real time only, got {','.join(self.wait_for)} in lock-step, where "
                              "the executor's clock paces the replayer (the executor's wait_for waits for everyone)")
        if self.samples_per_tick < 1:
            raise ConfigError(f"replayer.samples_per_tick: must be >= 1, got {self.samples_per_tick}")
        for name in ("heldout", "max_demos"):
            if getattr(self, name) < 0:
                raise ConfigError(f"replayer.{name}: must be >= 0, got {getattr(self, name)}")
        if any(c < 0 for c in self.classes) or any(i < 0 for i in self.indices):
            raise ConfigError("replayer.classes/indices: must be >= 0")
        if self.wait_timeout < 0:
            raise ConfigError(f"replayer.wait_timeout: must be >= 0, got {self.wait_timeout}")


def load_replay_library(cfg: ReplayerConfig) -> MotionLibrary:
    """The library named by ``cfg.library``, or the embedded synthetic one when it is unset.

    Raises:
        LibraryError: If the library file is missing or unreadable.
        ConfigError: If no library is given and the synthetic generator is not available.
        SceneError: If ``cfg.scene`` names no scene.
    """
    if cfg.library is not None:
        return load_library(cfg.library)
    scene = load_scene(cfg.scene or None)  # a misspelt scene is said before the generator's import
    try:
        from shared.synthetic import generate_library  # type: ignore[import-not-found]
    except ModuleNotFoundError as exc:
        if exc.name != "shared.synthetic":
            raise
        raise ConfigError("replayer.library: no library given and the embedded synthetic library "
                          "(shared.synthetic) is not available in this build; pass --library DIR_OR_NPZ, "
                          "e.g. --library ../shared/data/paper-library") from None
    # what `foresight train --scene` trains on by default: --seed selects from it
    return generate_library(seed=0, scene=scene)


def unused_options(cfg: ReplayerConfig) -> list[str]:
    """One line for each option set (not its default) that the chosen mode or library does not use.

    They were taken without a word: ``--rate-hz 5`` in lock-step streamed at the clock's pace all the same.
    """
    defaults = ReplayerConfig()
    unused = {"lockstep": ("rate_hz", "wait_timeout"), "realtime": ("samples_per_tick",)}[cfg.mode]
    out = [f"replayer.{name} = {getattr(cfg, name)} is unused in {cfg.mode} mode" for name in unused
           if getattr(cfg, name) != getattr(defaults, name)]
    if cfg.scene and cfg.library is not None:
        out.append(f"replayer.scene = {cfg.scene} is unused with a library given ({cfg.library}): it is the embedded "
                   "synthetic library's")
    return out


def _ranges(values: list[int]) -> str:
    """Sorted integers as runs: ``[0, 1, 2, 5, 7, 8]`` -> ``0..2, 5, 7..8``."""
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    return ", ".join(f"{a}..{b}" if b > a else str(a) for a, b in runs)


def select_demos(lib: MotionLibrary, cfg: ReplayerConfig) -> list[Demonstration]:
    """The demonstrations to stream, in streaming order.

    Held-out selection first (``heldout`` per class by ``seed``), then the ``classes`` and
    ``indices`` filters, then the optional seeded shuffle.

    Raises:
        ConfigError: If a class label is out of range or nothing is selected.
        LibraryError: If the held-out split is impossible.
        MappingError: If the library's features are not the ones ``HumanPose`` carries.
    """
    # the file given, and what it holds: an npz's source was named alone ("synthetic:table_8 classes=8 ...")
    named = f"{cfg.library} ({lib.source})" if cfg.library and str(cfg.library) != lib.source else lib.source
    require_mapping(lib.feature_names, "foresight replayer (HumanPose messages)", f"library {named}",
                    exact=LIVE_MAPPING)
    if not lib.demos:  # not the selection's fault: say so, not "no demonstration matches the selection"
        raise ConfigError(f"replayer.library: {named} holds no valid demonstration (see the warnings above)")
    bad = [c for c in cfg.classes if c >= lib.n_classes]
    if bad:
        raise ConfigError(f"replayer.classes: {bad} out of range, the library has {lib.n_classes} classes "
                          f"(0..{lib.n_classes - 1})")
    demos = heldout_split(lib, cfg.heldout, cfg.seed)[1] if cfg.heldout else list(lib.demos)
    if cfg.classes:
        wanted = set(cfg.classes)
        demos = [d for d in demos if d.label in wanted]
    chosen = demos
    if cfg.indices:
        wanted = set(cfg.indices)
        demos = [d for d in demos if d.index in wanted]
    if not demos:
        have = sorted({d.index for d in chosen})  # what --indices could have named, within --classes/--heldout
        known = f"; the indices there are {_ranges(have)}" if cfg.indices and have else ""
        raise ConfigError(f"replayer: no demonstration matches the selection (--classes/--indices/--heldout){known}")
    if cfg.shuffle:
        order = np.random.default_rng(cfg.seed).permutation(len(demos))
        demos = [demos[i] for i in order]
    return demos


@dataclass(frozen=True)
class ReplayEvent:
    """One element of the stream: a demonstration's start, one of its samples, or its end."""

    kind: str  # "start" | "pose" | "end"
    demo_id: int
    demo: Demonstration
    sample: int = -1


class ReplayerCore:
    """Deterministic schedule of the replayer's messages.

    Demonstrations are numbered by ``demo_id`` 0, 1, 2, ... in streaming order (looping keeps
    counting). Each one is ``start`` marker, its T poses, ``end`` marker.

    Args:
        demos: Demonstrations in streaming order (see :func:`select_demos`).
        loop: Start over after the last one.
        max_demos: Stop after this many demonstrations (0 = no limit).
    """

    def __init__(self, demos: list[Demonstration], loop: bool = False, max_demos: int = 0) -> None:
        if not demos:
            raise ValueError("ReplayerCore needs at least one demonstration")
        self.demos = list(demos)
        self.loop = loop
        self.max_demos = max_demos
        self._events = self._generate()
        self._peeked: ReplayEvent | None = None
        self._exhausted = False
        self.poses_emitted = 0
        self.demos_started = 0

    def _generate(self) -> Iterator[ReplayEvent]:
        demo_id = 0
        while True:
            for d in self.demos:
                if self.max_demos and demo_id >= self.max_demos:
                    return
                yield ReplayEvent("start", demo_id, d)
                for i in range(d.n_samples):
                    yield ReplayEvent("pose", demo_id, d, i)
                yield ReplayEvent("end", demo_id, d)
                demo_id += 1
            if not self.loop:
                return

    def _peek(self) -> ReplayEvent | None:
        if self._peeked is None and not self._exhausted:
            self._peeked = next(self._events, None)
            self._exhausted = self._peeked is None
        return self._peeked

    def _next(self) -> ReplayEvent | None:
        ev = self._peek()
        self._peeked = None
        return ev

    @property
    def done(self) -> bool:
        """True when every message has been emitted."""
        return self._peek() is None

    @property
    def total_poses(self) -> int | None:
        """Number of poses the whole stream holds (None when looping without a limit)."""
        if self.loop and not self.max_demos:
            return None
        if not self.max_demos:
            return sum(d.n_samples for d in self.demos)
        n = len(self.demos)
        return sum(self.demos[k % n].n_samples for k in range(self.max_demos if self.loop
                                                              else min(self.max_demos, n)))

    def step_events(self, n_poses: int) -> list[ReplayEvent]:
        """The next events holding ``n_poses`` poses (fewer at the end of the stream).

        Markers come with the poses they surround: a ``start`` marker in the step of its first pose,
        an ``end`` marker in the step of its last pose.
        """
        out: list[ReplayEvent] = []
        poses = 0
        while poses < n_poses:
            ev = self._next()
            if ev is None:
                break
            out.append(ev)
            if ev.kind == "pose":
                poses += 1
        nxt = self._peek()
        if poses and nxt is not None and nxt.kind == "end":
            out.append(self._next())  # type: ignore[arg-type]
        return out

    def step(self, n_poses: int, stamp: float, tick: int = -1, dt: float = 0.0) -> list[Message]:
        """The next messages: ``n_poses`` poses with their markers.

        Args:
            n_poses: Poses in this step (1 in real time, ``samples_per_tick`` in lock-step).
            stamp: Time of the first pose (s); pose j gets ``stamp + j * dt``.
            tick: Lock-step tick the poses belong to (-1 in real time).
            dt: Time between poses within the step (s).

        Returns:
            DemoMarker and HumanPose messages in publishing order. In lock-step the last pose has
            ``tick_last=True``; in real time every pose has it.
        """
        events = self.step_events(n_poses)
        n_pose_events = sum(1 for e in events if e.kind == "pose")
        msgs: list[Message] = []
        j = 0
        for ev in events:
            t = stamp + dt * min(j, max(n_pose_events - 1, 0)) if ev.kind != "end" else stamp + dt * max(j - 1, 0)
            if ev.kind == "pose":
                j += 1
                self.poses_emitted += 1
                msgs.append(HumanPose(stamp=float(t), tick=tick, tick_last=(tick < 0 or j == n_pose_events),
                                      demo_id=ev.demo_id, index=ev.sample,
                                      features=np.asarray(ev.demo.features[ev.sample], dtype=np.float64)))
            else:
                if ev.kind == "start":
                    self.demos_started += 1
                msgs.append(DemoMarker(stamp=float(t), tick=tick, demo_id=ev.demo_id, event=ev.kind,
                                       true_class=ev.demo.label, class_name=ev.demo.class_name,
                                       n_samples=ev.demo.n_samples))
        return msgs
