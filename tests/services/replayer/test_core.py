"""The replayer's pure schedule: selection, ordering, markers, lock-step batching, determinism."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from services.replayer.core import ReplayerConfig, ReplayerCore, load_replay_library, select_demos, unused_options
from shared.config import ConfigError
from shared.library import LibraryError, save_library
from shared.protocol import DemoMarker, HumanPose, decode, encode
from shared.scene import SceneError, load_scene
from shared.synthetic import generate_library


def drain(core: ReplayerCore, n: int = 1, **kw) -> list:
    out = []
    tick = 0
    while not core.done:
        out.append(core.step(n, stamp=float(tick), tick=tick if kw.get("lockstep") else -1, dt=0.01))
        tick += 1
    return out


def test_realtime_stream_order(small_lib):
    demos = select_demos(small_lib, ReplayerConfig())
    core = ReplayerCore(demos)
    assert core.total_poses == sum(d.n_samples for d in demos)
    msgs = [m for step in drain(core) for m in step]
    poses = [m for m in msgs if isinstance(m, HumanPose)]
    assert len(poses) == core.total_poses == core.poses_emitted
    assert all(p.tick == -1 and p.tick_last for p in poses)
    # start marker, T poses, end marker per demonstration, demo ids 0, 1, ...
    i = 0
    for demo_id, d in enumerate(demos):
        start, end = msgs[i], msgs[i + d.n_samples + 1]
        assert isinstance(start, DemoMarker) and (start.event, start.demo_id) == ("start", demo_id)
        assert (start.true_class, start.class_name, start.n_samples) == (d.label, d.class_name, d.n_samples)
        assert isinstance(end, DemoMarker) and (end.event, end.demo_id) == ("end", demo_id)
        body = msgs[i + 1:i + 1 + d.n_samples]
        assert [p.index for p in body] == list(range(d.n_samples))
        np.testing.assert_array_equal(np.stack([p.features for p in body]), d.features)
        i += d.n_samples + 2
    assert i == len(msgs)
    for m in msgs:
        decode(encode(m))  # every message is valid on the wire


def test_each_step_one_pose_with_its_markers(small_lib):
    core = ReplayerCore(select_demos(small_lib, ReplayerConfig(classes=[0], indices=[0])))
    steps = drain(core)
    assert len(steps) == 12
    assert [type(m).__name__ for m in steps[0]] == ["DemoMarker", "HumanPose"]
    assert [type(m).__name__ for m in steps[-1]] == ["HumanPose", "DemoMarker"]
    assert all(len(s) == 1 for s in steps[1:-1])


@pytest.mark.parametrize("n", [1, 3, 5])
def test_lockstep_batches(small_lib, n):
    demos = select_demos(small_lib, ReplayerConfig(classes=[1]))
    core = ReplayerCore(demos)
    steps = drain(core, n, lockstep=True)
    total = sum(d.n_samples for d in demos)
    assert len(steps) == -(-total // n)
    for tick, step in enumerate(steps):
        poses = [m for m in step if isinstance(m, HumanPose)]
        assert len(poses) == (n if tick < len(steps) - 1 else total - n * (len(steps) - 1))
        assert all(m.tick == tick for m in step)
        assert [p.tick_last for p in poses] == [False] * (len(poses) - 1) + [True]
        np.testing.assert_allclose([p.stamp for p in poses], tick + 0.01 * np.arange(len(poses)))
    markers = [m for s in steps for m in s if isinstance(m, DemoMarker)]
    assert [(m.demo_id, m.event) for m in markers] == [(k, e) for k in range(4) for e in ("start", "end")]


def test_loop_and_max_demos(small_lib):
    demos = select_demos(small_lib, ReplayerConfig(classes=[2], indices=[0, 1]))
    core = ReplayerCore(demos, loop=True, max_demos=5)
    assert core.total_poses == 12 + 13 + 12 + 13 + 12
    markers = [m for s in drain(core) for m in s if isinstance(m, DemoMarker) and m.event == "start"]
    assert [(m.demo_id, m.n_samples) for m in markers] == [(0, 12), (1, 13), (2, 12), (3, 13), (4, 12)]
    assert ReplayerCore(demos, loop=True).total_poses is None
    core = ReplayerCore(demos, max_demos=1)
    assert len([m for s in drain(core) for m in s if isinstance(m, HumanPose)]) == 12


def test_selection(small_lib):
    sel = select_demos(small_lib, ReplayerConfig(classes=[0, 2], indices=[1, 3]))
    assert [(d.label, d.index) for d in sel] == [(0, 1), (0, 3), (2, 1), (2, 3)]
    held = select_demos(small_lib, ReplayerConfig(heldout=1, seed=5))
    assert [d.label for d in held] == [0, 1, 2]
    assert [(d.label, d.index) for d in held] == [(d.label, d.index) for d in
                                                  select_demos(small_lib, ReplayerConfig(heldout=1, seed=5))]
    sh1 = select_demos(small_lib, ReplayerConfig(shuffle=True, seed=1))
    sh2 = select_demos(small_lib, ReplayerConfig(shuffle=True, seed=1))
    assert [d.source for d in sh1] == [d.source for d in sh2] != [d.source for d in small_lib.demos]
    assert sorted(d.source for d in sh1) == sorted(d.source for d in small_lib.demos)


def test_selection_errors(small_lib):
    with pytest.raises(ConfigError, match=r"replayer.classes: \[5\] out of range"):
        select_demos(small_lib, ReplayerConfig(classes=[5]))
    have = sorted({d.index for d in small_lib.demos})
    with pytest.raises(ConfigError, match=rf"no demonstration matches .*; the indices there are 0\.\.{have[-1]}$"):
        select_demos(small_lib, ReplayerConfig(indices=[99]))  # it did not say which indices there are
    with pytest.raises(LibraryError, match="cannot hold out 4"):
        select_demos(small_lib, ReplayerConfig(heldout=4))
    empty = dataclasses.replace(small_lib, demos=[])  # every block refused on loading: no selection to blame
    with pytest.raises(ConfigError, match=r"^replayer.library: .* holds no valid demonstration \(see the warnings"):
        select_demos(empty, ReplayerConfig())
    # the file given, then what it holds: an npz's own source alone ("synthetic:table_8 ...") named no file
    with pytest.raises(ConfigError, match=rf"^replayer.library: /data/mine.npz \({re.escape(empty.source)}\) holds no"):
        select_demos(empty, ReplayerConfig(library=Path("/data/mine.npz")))


@pytest.mark.parametrize(("field", "value", "pattern"), [
    ("rate_hz", 0.0, "rate_hz"), ("samples_per_tick", 0, "samples_per_tick"),
    ("heldout", -1, "heldout"),
    ("max_demos", -2, "max_demos"), ("classes", [-1], "classes"), ("wait_timeout", -1.0, "wait_timeout"),
])
def test_config_validation(field, value, pattern):
    with pytest.raises(ConfigError, match=pattern):
        dataclasses.replace(ReplayerConfig(), **{field: value}).validate()


def test_waiting_for_services_is_real_time_only() -> None:
    """``--mode lockstep --wait-for predictor`` was taken and ignored without a word."""
    ReplayerConfig(wait_for=["predictor"]).validate()
    with pytest.raises(ConfigError, match="replayer.wait_for: real time only, got predictor,planner in lock-step"):
        ReplayerConfig(mode="lockstep", wait_for=["predictor", "planner"]).validate()


def test_load_replay_library(small_lib, tmp_path):
    save_library(small_lib, tmp_path / "lib.npz")
    lib = load_replay_library(ReplayerConfig(library=tmp_path / "lib.npz"))
    assert len(lib.demos) == len(small_lib.demos)
    with pytest.raises(LibraryError, match="not found"):
        load_replay_library(ReplayerConfig(library=tmp_path / "none"))
    try:
        import shared.synthetic  # noqa: F401
    except ModuleNotFoundError:
        with pytest.raises(ConfigError, match="pass --library"):
            load_replay_library(ReplayerConfig())
    else:
        assert load_replay_library(ReplayerConfig()).n_classes >= 1


@pytest.mark.parametrize(("change", "match"), [
    ({"seed": -1}, r"^replayer\.seed: must be >= 0, got -1$"),
    ({"rate_hz": 1e-12}, r"^replayer\.rate_hz: must be in \[0\.01, 10000\]"),
    ({"rate_hz": 0.0}, r"^replayer\.rate_hz: must be in"),
    ({"stop_with": ["exeuctor"]}, r"^replayer\.stop_with: unknown service 'exeuctor' \(did you mean 'executor'\?\)$"),
    ({"wait_for": ["predictr"]}, r"^replayer\.wait_for: unknown service 'predictr' \(did you mean 'predictor'\?\)$"),
    ({"wait_for": ["replayer"]}, r"^replayer\.wait_for: unknown service 'replayer'"),
])
def test_values_that_used_to_fail_later_are_config_errors(change, match) -> None:
    """A negative seed was a numpy traceback, a tiny rate an OverflowError mid-stream, a misspelt --stop-with a run
    that never ended."""
    with pytest.raises(ConfigError, match=match):
        ReplayerConfig(**change).validate()
    ReplayerConfig(wait_for=["predictor", "planner"], stop_with=["executor"], rate_hz=0.01).validate()


def test_the_embedded_library_is_the_trainers_whatever_the_seed() -> None:
    """--seed selects and shuffles; the library it selects from is the one `foresight train` fits (seed 0)."""
    a, b = load_replay_library(ReplayerConfig(seed=0)), load_replay_library(ReplayerConfig(seed=3))
    assert len(a.demos) == len(b.demos)
    assert all(np.array_equal(x.features, y.features) for x, y in zip(a.demos, b.demos, strict=True))


def test_the_embedded_library_is_for_the_scene_given() -> None:
    """The built-in library was always the default scene's: a run on another scene (`foresight train --scene`)
    streamed reaches for cups that are not there. A misspelt scene is one line, as the other services say it."""
    side = load_replay_library(ReplayerConfig(scene="pr2_two_cups_side"))
    trained = generate_library(seed=0, scene=load_scene("pr2_two_cups_side"))  # `foresight train --scene`'s
    np.testing.assert_array_equal(side.demos[0].features, trained.demos[0].features)
    assert not np.array_equal(side.demos[0].features, load_replay_library(ReplayerConfig()).demos[0].features)
    with pytest.raises(SceneError):
        load_replay_library(ReplayerConfig(scene="no_such_scene"))


def test_options_the_mode_does_not_use_are_said(tmp_path) -> None:
    """--rate-hz in lock-step, --samples-per-tick in real time were taken without a word; so was a scene beside a
    library of its own."""
    assert unused_options(ReplayerConfig(mode="lockstep", samples_per_tick=4)) == []
    assert unused_options(ReplayerConfig(samples_per_tick=1, rate_hz=10.0)) == []
    assert unused_options(ReplayerConfig(mode="lockstep", rate_hz=10.0, wait_timeout=5.0)) == [
        "replayer.rate_hz = 10.0 is unused in lockstep mode", "replayer.wait_timeout = 5.0 is unused in lockstep mode"]
    assert unused_options(ReplayerConfig(samples_per_tick=4)) == ["replayer.samples_per_tick = 4 is unused in "
                                                                  "realtime mode"]
    lines = unused_options(ReplayerConfig(scene="pr2_two_cups_side", library=tmp_path))
    assert len(lines) == 1 and "replayer.scene = pr2_two_cups_side is unused with a library given" in lines[0]
