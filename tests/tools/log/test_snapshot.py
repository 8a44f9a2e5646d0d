"""``foresight log snapshot``: the scene replayed from the logged Foxglove channels, drawn to a PNG."""

from __future__ import annotations

import itertools
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from shared.foxglove.decode import read_scene
from shared.foxglove.scene import CHOSEN_RGBA, SceneBuilder
from shared.protocol import ClassPosterior, HumanPose, Keys, OccupancyGrid, encode
from shared.recording.reader import read_log
from shared.recording.writer import McapLog
from shared.scene import load_scene
from tools.log.cli import main
from tools.log.snapshot import SceneState, draw_snapshot, scene_at
from tools.log.steps import decode_all

KEYS = Keys()
PNG = b"\x89PNG\r\n\x1a\n"


def _logged_voxels(path: Path, index: int) -> int:
    """Voxels >= 0.05 probability in the ``index``-th logged OccupancyGrid (Foresight's own message)."""
    lf = read_log(path, keep=lambda ch: ch.schema_name == "foresight.OccupancyGrid")
    occ = decode_all(lf, "foresight.OccupancyGrid", OccupancyGrid)[index][1]
    return int(np.count_nonzero(occ.values.astype(np.float64) / 255.0 >= 0.05))


def _thickest(state: SceneState) -> tuple[int, object]:
    lines = list(state.entity("plan/paths").lines)
    k = int(np.argmax([ln.thickness for ln in lines]))
    return k, lines[k]


def test_last_plan_by_default(run_log, robot) -> None:
    state = scene_at(run_log, None)
    assert state.entities["/viz/scene"].keys() == {"obstacles", "cup/blue_cup", "cup/red_cup"}
    assert state.entity("obstacles").cubes and state.entity("cup/red_cup").cylinders
    assert len(state.entity("robot/spheres").spheres) == len(robot.sphere_radii)
    assert state.costs["step"] == 1 and state.costs["chosen"] == "red_cup"
    k, chosen = _thickest(state)
    assert k == 1 and len(state.entity("plan/paths").lines) == 2 and len(chosen.points) == 12
    assert (chosen.color.r, chosen.color.g, chosen.color.b) == pytest.approx(CHOSEN_RGBA[:3])
    n = _logged_voxels(run_log, -1)
    assert n > 0 and len(state.voxels) == len(state.probability) == len(state.rgba) == n
    assert state.probability.min() >= 0.05 and state.rgba.dtype == np.uint8
    assert {"robot_base", "end_effector"} <= state.frames.keys() and state.posterior is None
    assert state.t_s > 0 and state.summary().startswith(f"t={state.t_s:.3f}s, {n} voxels, step 1, chosen red_cup")


def test_at_a_time_replays_up_to_it(run_log) -> None:
    records = list(read_scene(run_log))
    t0 = records[0].log_time
    first_plan = next(r.log_time for r in records if r.topic == "/viz/plan")
    state = scene_at(run_log, (first_plan - t0) / 1e9)
    assert state.costs["step"] == 0 and state.costs["chosen"] == "blue_cup" and _thickest(state)[0] == 0
    start = scene_at(run_log, 0.0)
    assert set(start.entities) == {"/viz/scene"} and len(start.voxels) == 0 and start.costs is None
    late = scene_at(run_log, 3600.0)  # past the end: the last state, at the last record's time
    assert late.costs["step"] == 1 and late.t_s == pytest.approx((records[-1].log_time - t0) / 1e9)


def test_cli_writes_a_png(run_log, tmp_path, capsys) -> None:
    out = tmp_path / "snap.png"
    assert main(["snapshot", str(run_log), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    n = _logged_voxels(run_log, -1)
    assert len(lines) == 1 and lines[0].startswith(f"wrote {out} (t=") and f"{n} voxels" in lines[0]
    assert "chosen red_cup" in lines[0]
    assert out.read_bytes()[:8] == PNG
    assert main(["snapshot", str(run_log), "--out", str(out), "--at", "1000"]) == 0
    assert "--at 1000 s is past the end of the scene" in capsys.readouterr().err  # it drew the end without a word
    import matplotlib.image as mpimg

    img = mpimg.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 1000
    assert len(np.unique(img.reshape(-1, img.shape[-1]), axis=0)) > 50  # something was drawn
    copy = tmp_path / "run.mcap"
    shutil.copy(run_log, copy)
    assert main(["snapshot", str(copy), "--at", "0"]) == 0
    assert "0 voxels" in capsys.readouterr().out and (tmp_path / "run-snapshot.png").read_bytes()[:8] == PNG


def test_human_and_posterior_are_drawn(robot, tmp_path) -> None:
    from shared.human import HumanModel, place_in_scene

    scene = load_scene(None)
    path = tmp_path / "human.mcap"
    clock = itertools.count(1_000_000_000, 1_000_000)
    log = McapLog(path, KEYS, SceneBuilder(scene, robot, HumanModel(), place_in_scene), clock=lambda: next(clock),
                  viz_thread=False)
    feats = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])
    log.on_sample(KEYS.pose, encode(HumanPose(stamp=0.0, tick=0, tick_last=True, demo_id=1, index=0, features=feats)))
    log.on_sample(KEYS.posterior, encode(ClassPosterior(stamp=0.0, tick=0, demo_id=1, index=0,
                                                        class_names=["blue_cup", "red_cup"],
                                                        posterior=np.array([0.2, 0.8]),
                                                        log_likelihood=np.array([-3.0, -1.0]))))
    log.close()
    state = scene_at(path, None)  # no plan: everything
    body = state.entity("human/body")
    assert body is not None and body.lines and all(len(ln.points) == 2 and ln.thickness > 0 for ln in body.lines)
    assert "recognised red_cup (p=0.80)" in state.summary() and "chosen -" in state.summary()
    out = draw_snapshot(state, tmp_path / "deep" / "human.png", title="human")
    assert out.read_bytes()[:8] == PNG


def test_keypoints_are_gone_once_their_lifetime_ends_as_foxglove_shows_them(robot, tmp_path) -> None:
    """A snapshot 3.9 s after the last keypoints still drew them (lifetime 0.5 s): Foxglove had removed them."""
    from shared.foxglove.keypoints import LIFETIME_S
    from shared.human import HumanModel, place_in_scene
    from shared.keypoints.fit import POINT_NAMES
    from shared.protocol import DemoMarker, HumanKeypoints, RobotState

    scene = load_scene(None)
    path = tmp_path / "kp.mcap"
    now = [1_000_000_000]
    log = McapLog(path, KEYS, SceneBuilder(scene, robot, HumanModel(), place_in_scene), clock=lambda: now[0],
                  viz_thread=False)
    feats = np.array([0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 0.0, 0.2, 0.1, 0.3, 0.0, 0.5])
    log.on_sample(KEYS.demo, encode(DemoMarker(stamp=0.0, tick=-1, demo_id=1, event="start", true_class=0,
                                               class_name="blue_cup", n_samples=5)))
    log.on_sample(KEYS.pose, encode(HumanPose(stamp=0.0, tick=-1, tick_last=True, demo_id=1, index=0,
                                              features=feats)))
    log.on_sample(KEYS.keypoints, encode(HumanKeypoints(stamp=0.0, tick=-1, frame=0, frame_id="sensor",
                                                        names=list(POINT_NAMES),
                                                        positions=HumanModel().joint_positions(feats))))
    for n in range(1, 31):  # 6 s of the robot, no keypoints: the sensor stopped
        now[0] += 200_000_000
        log.on_sample(KEYS.robot_state, encode(RobotState(stamp=0.2 * n, tick=-1, joint_names=robot.joint_names,
                                                          goal=-1, reached=False, holding=True, reason="",
                                                          q=robot.q_start.numpy().astype(np.float64), qd=np.zeros(8))))
    log.close()
    assert scene_at(path, LIFETIME_S / 2).entity("human/keypoints") is not None
    assert scene_at(path, 5.0).entity("human/keypoints") is None
    assert scene_at(path, 5.0).entity("human/body") is not None  # no lifetime: it stays


@pytest.mark.parametrize("argv, message", [
    (["snapshot", "/nonexistent.mcap"], "not found"),
    (["snapshot", "{tmp}"], "is a directory"),  # it said 'not found'
    (["snapshot", "{pipe}"], "is not a regular file (a pipe?)"),
    (["snapshot", "{bad}"], "not an MCAP file"),
    (["snapshot", "{log}", "--at", "-1"], "--at must be a finite time >= 0"),
    (["snapshot", "{log}", "--at", "inf"], "--at must be a finite time >= 0"),
    (["snapshot", "{empty}"], "no scene channels"),
    (["snapshot", "{log}", "--out", "{tmp}/notapng"], "ending in .png"),  # it said 'wrote notapng', wrote notapng.png
    (["snapshot", "{log}", "--out", ""], "--out: empty"),
])
def test_errors_are_one_line(run_log, tmp_path, capsys, argv, message) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"hello, this is not mcap at all")
    empty = tmp_path / "empty.mcap"
    McapLog(empty, KEYS).close()
    os.mkfifo(pipe := tmp_path / "pipe")
    argv = [a.format(log=run_log, bad=bad, empty=empty, tmp=tmp_path, pipe=pipe) for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code not in (0, None)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "bad-snapshot.png").exists()


def test_a_run_s_directory_with_one_log_is_that_log(run_log, tmp_path) -> None:
    """`foresight log snapshot runs/demo/latest` (the README's commands) read the directory's one log; the scene's
    indexed reader opened the directory itself ('Is a directory')."""
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(run_log, run / "run.mcap")
    (run / "executor.log").write_text("the services' logs sit beside it\n")
    assert scene_at(run, None).summary() == scene_at(run_log, None).summary()
    assert main(["table", str(run)]) == 0


def test_the_summary_names_no_class_for_a_flat_posterior_as_the_table() -> None:
    """`log snapshot --at 0.3` said "recognised blue_cup (p=0.15)" where `log table` said "(flat) p=0.14"; a log
    written before the chart applied the rule still names the top class in "recognised"."""
    names = ["blue_cup", "red_cup", "near_left", "far_left", "near_centre", "near_right", "far_right", "right_edge"]
    flat = {"probability": dict(zip(names, [0.15] + [0.85 / 7] * 7, strict=True)), "recognised": "blue_cup",
            "recognised_probability": 0.15}
    assert "recognised none (flat, p=0.15)" in SceneState(posterior=flat).summary()
    sure = {"probability": dict(zip(names, [0.3] + [0.7 / 7] * 7, strict=True)), "recognised": "blue_cup"}
    assert "recognised blue_cup (p=0.30)" in SceneState(posterior=sure).summary()
    assert "recognised -" in SceneState().summary()


def test_a_time_too_large_for_nanoseconds_draws_the_end(run_log, tmp_path, capsys) -> None:
    """``--at 1e300`` (finite) overflowed converting to nanoseconds: an OverflowError traceback."""
    out = tmp_path / "end.png"
    assert main(["snapshot", str(run_log), "--out", str(out), "--at", "1e300"]) == 0
    assert "past the end of the scene" in capsys.readouterr().err and out.read_bytes()[:8] == PNG
    assert scene_at(run_log, 1e300).t_s == scene_at(run_log, 1000.0).t_s
