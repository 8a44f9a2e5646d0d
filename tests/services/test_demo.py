"""``foresight demo``: the four services as processes, lock-step, summary and MCAP (issue 5, integration b)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from services.demo import DemoConfig, main
from services.run_table import table_header
from shared.config import ConfigError
from shared.library import save_library
from shared.synthetic import generate_library


@pytest.mark.slow
def test_demo_multiprocess_json(tmp_path: Path) -> None:
    lib = tmp_path / "lib.npz"
    save_library(generate_library(8, 6, seed=3), lib)
    cmd = [sys.executable, "-m", "tools", "demo", "--steps", "5", "--library", str(lib), "--components", "4",
           "--models-dir", str(tmp_path / "models"), "--run-dir", str(tmp_path / "run"), "--json", "--timeout", "400"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=480, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout)
    for key in ("steps", "chosen_goal_per_step", "switch_step", "interference_cost", "mcap_path", "run_dir",
                "figure", "comparison"):
        assert key in summary
    assert len(summary["steps"]) == 5 and len(summary["chosen_goal_per_step"]) == 5
    assert set(summary["chosen_goal_per_step"]) <= {"blue_cup", "red_cup"}
    assert summary["interference_cost"] >= 0.0
    with open(summary["mcap_path"], "rb") as f:
        reader = make_reader(f)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        n = sum(1 for _ in reader.iter_messages())
    assert "foresight/planner/plan" in topics and "foresight/robot/state" in topics and n > 0
    run_dir = Path(summary["run_dir"])  # the run's own directory, beside the others' and `latest`
    assert run_dir.parent == tmp_path / "run" and (tmp_path / "run" / "latest").resolve() == run_dir.resolve()
    assert Path(summary["mcap_path"]).parent == run_dir
    for name in ("predictor", "planner", "replayer", "executor"):
        assert (run_dir / f"{name}.log").is_file()
    assert Path(summary["figure"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (row,) = summary["comparison"]  # one planner: the prediction
    assert row["planner"] == "prediction" and row["contact_s"] >= 0.0 and row["near_s"] >= row["contact_s"]
    assert "verdict" not in summary  # a verdict needs --compare
    # the live progress (stderr with --json): the run's length, then one table with a header and a row
    # per step, in order, agreeing with the summary
    progress = proc.stderr.splitlines()
    assert any("lockstep mode, 5 steps of 0.5 s" in ln for ln in progress)
    # the start-up says each service as it comes up (it was silent for 20-40 s before the table)
    ups = [ln.split(": ", 1)[1].split(" (")[0] for ln in progress if re.match(r"foresight demo: \w+ up \(", ln)]
    assert ups == ["predictor up", "planner up", "replayer up"]
    header = table_header(summary["goal_names"])
    assert progress.count(header) == 1
    rows = progress[progress.index(header) + 1:][:5]
    assert [r.split()[0] for r in rows] == ["0", "1", "2", "3", "4"]
    assert [r.split()[2] for r in rows] == summary["chosen_goal_per_step"]
    assert [float(r.split()[1]) for r in rows] == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0])
    # the live belief is the one each plan was made with, as --json and `foresight log table` give it (the live
    # column printed whichever posterior had come last: one step early, and not the same from run to run)
    assert [" ".join(r.split()[-2:]) if "p=" in r else "" for r in rows] == [e["belief"] for e in summary["steps"]]


def test_demo_bad_input_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        main(["--library", str(tmp_path / "missing"), "--run-dir", str(tmp_path)])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "missing" in err
    with pytest.raises(SystemExit):
        main(["--steps", "0"])
    assert "demo.steps: must be >= 1" in capsys.readouterr().err
    for flag, name in (("--period-s", "period_s"), ("--rate-hz", "rate_hz"), ("--timeout", "timeout")):
        with pytest.raises(SystemExit):
            main([flag, "0"])
        assert f"demo.{name}: must be > 0, got 0.0" in capsys.readouterr().err  # it named all three
    with pytest.raises(SystemExit):
        main(["--goals", "red_cup,green_cup", "--run-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert "demo.goals: 'green_cup' not a cup of scene pr2_two_cups_side (its cups: blue_cup, red_cup)" in err
    with pytest.raises(SystemExit):  # the planner refused it, after the demo's start-up
        main(["--goals", "red_cup,red_cup", "--run-dir", str(tmp_path)])
    assert "demo.goals: each cup once, got red_cup,red_cup" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_drives_the_simulated_ros2_robot(tmp_path: Path) -> None:
    """``--robot ros2-sim``: the executor drives `foresight simrobot` (a process) over rmw_zenoh, lock-step."""
    lib = tmp_path / "lib.npz"
    save_library(generate_library(8, 6, seed=3), lib)
    cmd = [sys.executable, "-m", "tools", "demo", "--steps", "4", "--library", str(lib), "--components", "4",
           "--models-dir", str(tmp_path / "models"), "--run-dir", str(tmp_path / "run"), "--json", "--timeout", "400",
           "--robot", "ros2-sim", "--ros2"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=480, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout)
    assert len(summary["chosen_goal_per_step"]) == 4 and "faults" not in proc.stderr
    with open(summary["mcap_path"], "rb") as f:
        channels = {c.topic: c.message_encoding for c in make_reader(f).get_summary().channels.values()}
    assert channels["/joint_states"] == channels["/r_arm_controller/joint_trajectory"] == channels["/clock"] == "cdr"
    robot_log = (Path(summary["run_dir"]) / "simrobot.log").read_text()
    assert "0 samples refused (none)" in robot_log and " 0 trajectories received" not in robot_log
    ros2_log = (Path(summary["run_dir"]) / "ros2.log").read_text()
    assert "/joint_states 0," in ros2_log, "the gateway leaves /joint_states to the robot"
    assert "; refused none" in ros2_log


def test_demo_refuses_a_ros2_robot_with_security(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        main(["--robot", "ros2-sim", "--security", str(tmp_path)])
    assert e.value.code == 2
    assert "demo.robot with demo.security" in capsys.readouterr().err


def test_demo_prepare_writes_the_inputs_and_the_services_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                                 ) -> None:
    """``--prepare DIR``: the human's demonstration, the model, DIR/foresight.toml that each service reads."""
    import tomllib

    from shared.library import load_library

    lib = tmp_path / "lib.npz"
    save_library(generate_library(8, 6, seed=3), lib)
    out = tmp_path / "compose"
    assert main(["--prepare", str(out), "--library", str(lib), "--components", "4", "--steps", "5",
                 "--models-dir", str(tmp_path / "models")]) == 0
    config = tomllib.loads((out / "foresight.toml").read_text())
    assert set(config) == {"predictor", "planner", "replayer", "executor", "view"}  # view: compose's profile live
    assert Path(config["predictor"]["model"]).is_file() and Path(config["predictor"]["model"]).parent == \
        tmp_path / "models"
    human = load_library(config["replayer"]["library"])
    assert len(human.demos) == 1 and config["replayer"]["samples_per_tick"] >= 1
    assert config["executor"]["steps"] == 5 and config["planner"]["velocity_scale"] == 0.1
    assert config["planner"]["goals"] == ["red_cup"]  # Table I's one task, as the demo runs it
    assert "foresight.toml" in capsys.readouterr().out
    assert not list(tmp_path.glob("run*")), "nothing was run"


def test_demo_live_takes_a_port_or_foxgloves_default(capsys: pytest.CaptureFixture[str]) -> None:
    from services.demo_services import service_options

    with pytest.raises(SystemExit):
        main(["--live", "--steps", "0"])  # a bare --live does not swallow the next option
    assert "demo.steps: must be >= 1" in capsys.readouterr().err
    for flag, name in (("--period-s", "period_s"), ("--rate-hz", "rate_hz"), ("--timeout", "timeout")):
        with pytest.raises(SystemExit):
            main([flag, "0"])
        assert f"demo.{name}: must be > 0, got 0.0" in capsys.readouterr().err  # it named all three
    for value, message in (("70000", "demo.live: must be a port"), ("-1", "demo.live: must be a port"),
                           ("abc", "--live: expected int, got 'abc'")):  # a usage and "unrecognized arguments"
        with pytest.raises(SystemExit):
            main(["--live", value])
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    opts = service_options(DemoConfig(live=8765), Path("m.npz"), Path("h.npz"), 3, None)
    live = opts["executor"].index("--live-port")  # the executor serves the scene it logs
    assert opts["executor"][live + 1] == "8765" and "--live-port" not in service_options(
        DemoConfig(), Path("m.npz"), Path("h.npz"), 3, None)["executor"]


def test_demo_human_as_keypoints_plays_them_through_the_tracker(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                                  ) -> None:
    """``--human keypoints``: the human's demonstration as a noisy keypoint recording, the tracker in the replayer's
    place (its config from --prepare, which writes what the demo runs), real time only."""
    import tomllib

    import numpy as np

    from services.demo_services import KEYPOINT_REST_S
    from shared.keypoints.library import read_keypoint_csv
    from shared.library import load_library

    with pytest.raises(SystemExit):
        main(["--human", "keypoints"])  # lock-step: the tracker runs on the wall clock
    assert "add --mode realtime" in capsys.readouterr().err
    lib = tmp_path / "lib.npz"
    save_library(generate_library(8, 6, seed=3), lib)
    out = tmp_path / "compose"
    assert main(["--prepare", str(out), "--library", str(lib), "--components", "4", "--mode", "realtime",
                 "--human", "keypoints", "--keypoint-noise-m", "0.02", "--models-dir", str(tmp_path / "models")]) == 0
    config = tomllib.loads((out / "foresight.toml").read_text())
    assert set(config) == {"predictor", "planner", "tracker", "executor", "view"}
    assert config["executor"]["wait_for"] == ["tracker", "predictor", "planner"]
    # the whole run, not the executor alone: by hand, the reach was played while the planner was still starting
    assert config["tracker"]["wait_for"] == ["predictor", "planner", "executor"] and config["tracker"]["lead_s"] == 0.0
    (demo,) = read_keypoint_csv(Path(config["tracker"]["from_file"]))
    (human,) = load_library(out / "human.npz").demos
    rest = round(KEYPOINT_REST_S * 30)
    assert len(demo.frames) == human.n_samples + 2 * rest  # the person at rest before and after the reach
    spread = np.std(demo.positions[:rest, 0], axis=0)  # fresh noise on every frame of the rest
    assert np.all((spread > 0.01) & (spread < 0.03))


def test_a_prefix_zenoh_refuses_is_a_config_error() -> None:
    """It reached the router's first key declaration and ended in a 29-line ZError traceback."""
    from services.demo import DemoConfig
    from shared.config import ConfigError

    for prefix in ("a*b", "a//b"):
        with pytest.raises(ConfigError, match=rf"^demo\.prefix: '{re.escape(prefix)}' must be a Zenoh key"):
            DemoConfig(prefix=prefix).validate()
    for prefix in ("foresight ", "fore\tsight", "a\x00b"):  # Zenoh takes them: a key space no other service meets
        with pytest.raises(ConfigError, match=r"^demo\.prefix: .* has a space or a control character"):
            DemoConfig(prefix=prefix).validate()


def test_a_run_that_fails_before_its_services_leaves_no_run_directory(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A bad option found while preparing left an empty run directory, and moved `latest` to it."""
    runs = tmp_path / "runs"
    (runs / "20260101T000000Z-lockstep").mkdir(parents=True)
    (runs / "latest").symlink_to("20260101T000000Z-lockstep", target_is_directory=True)
    for _ in range(3):
        with pytest.raises(SystemExit):
            main(["--goals", "red_cup,green_cup", "--run-dir", str(runs), "--models-dir", str(tmp_path / "m")])
    assert "green_cup" in capsys.readouterr().err
    assert sorted(p.name for p in runs.iterdir()) == ["20260101T000000Z-lockstep", "latest"]
    assert (runs / "latest").resolve() == (runs / "20260101T000000Z-lockstep").resolve()


def test_unusable_models_dir_and_taken_live_port_are_found_before_any_work(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Both were found only after training (about 50 s) or after the four services had started."""
    import socket

    (tmp_path / "afile").write_text("")
    with pytest.raises(SystemExit) as exc:
        main(["--models-dir", str(tmp_path / "afile" / "models"), "--run-dir", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "demo.models_dir" in err and "a file is in the way" in err, err
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(SystemExit) as exc:
            main(["--live", str(port), "--run-dir", str(tmp_path / "runs"), "--models-dir", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and f"demo.live: port {port} on 127.0.0.1 is taken" in err, err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_a_picture_that_cannot_be_written_costs_a_warning_not_the_runs_outcome(tmp_path: Path) -> None:
    """A full disk used to end the demo in 'error: No space left on device', its 20 steps' outcome lost."""
    from services.demo_closing import picture as _picture

    lines: list[str] = []
    png = tmp_path / "run.png"

    def full_disk(path: Path) -> Path:
        path.write_bytes(b"")  # what matplotlib leaves: an empty file
        raise OSError(28, "No space left on device", str(path))

    assert _picture(full_disk, png, lines.append) is None
    assert lines == [f"foresight demo: warning: the picture of the run was not drawn: {png}: No space left on device"]
    assert not png.exists()
    assert _picture(lambda p: p, png, lines.append) == png and len(lines) == 1


def test_the_demos_config_file_reaches_its_services_and_is_checked_whole(tmp_path: Path, monkeypatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``--config FILE`` applied its [demo] section only (FORESIGHT_CONFIG=FILE reached the services); a typo in
    another section, or a bad value in the environment, ran without a word."""
    from services.demo import DemoConfig
    from services.demo_inputs import share_config_file

    monkeypatch.setenv("FORESIGHT_CONFIG", "")  # recorded as unset: whatever the demo sets, the test's end unsets
    monkeypatch.delenv("FORESIGHT_CONFIG")
    good = tmp_path / "good.toml"
    good.write_text("[planner.cost]\nw_human = 0\n")
    share_config_file(str(good), DemoConfig())
    assert os.environ["FORESIGHT_CONFIG"] == str(good.resolve())  # what every service process inherits
    for text, named in (("[planner.stmp]\niterations = 10\n", "unknown table; did you mean [planner.stomp]?"),
                        ("[replayer]\nrate_hz = -1\n", "replayer.rate_hz")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(SystemExit) as e:
            main(["--config", str(bad), "--run-dir", str(tmp_path / "run")])
        assert e.value.code == 2 and named in capsys.readouterr().err
    monkeypatch.delenv("FORESIGHT_CONFIG")
    monkeypatch.setenv("FORESIGHT_REPLAYER_RATE_HZ", "fast")
    with pytest.raises(SystemExit):
        main(["--run-dir", str(tmp_path / "run")])
    assert "FORESIGHT_REPLAYER_RATE_HZ: expected float, got 'fast'" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()  # refused before anything ran
    monkeypatch.undo()
    assert "FORESIGHT_CONFIG" not in os.environ  # the demo set it for its services: not for the next test


def test_a_real_time_run_that_ends_before_the_goal_says_why_and_what_to_do() -> None:
    """`make demo DEMO_ARGS=--mode realtime` ended with 'goal reached: no' and nothing explaining it."""
    import dataclasses

    from services.demo import DemoConfig
    from services.demo_closing import closing_lines as _closing_lines
    from services.scenario import Summary

    summary = Summary(steps=[], chosen_goal_per_step=[], switch_step=None, interference_cost=0.0, mcap_path="x.mcap",
                      reached=False, reached_step=None, human_class="blue_cup", recognised_class="blue_cup",
                      extra={"run_dir": "runs/demo/x"})
    cfg = dataclasses.replace(DemoConfig(), mode="realtime", steps=20, period_s=0.5, robot_speed=0.1)
    note = [ln for ln in _closing_lines(cfg, summary) if ln.startswith("note: a real-time run lasts")]
    assert len(note) == 1 and "(10 s) and goes on until the robot arrives, at most 10 s more" in note[0]
    assert "--steps 40" in note[0]
    note = [ln for ln in _closing_lines(dataclasses.replace(cfg, finish=False), summary) if ln.startswith("note: ")]
    assert len(note) == 1 and "goes on" not in note[0] and "--finish lets it go on to its goal" in note[0]
    late = dataclasses.replace(summary, reached=True, reached_t_s=14.6)  # it went on after its 10 s: said so
    note = [ln for ln in _closing_lines(cfg, late) if ln.startswith("note: ")]
    assert note == ["note: the robot arrived 4.6 s after the run's 10 s: the run goes on until it is there "
                    "(--no-finish ends it at 10 s)"]
    note = [ln for ln in _closing_lines(dataclasses.replace(cfg, compare=True), late) if ln.startswith("note: ")]
    assert note[0].startswith("note: the prediction planner's robot arrived 4.6 s")  # printed after the no-human-cost
    # run's table, "the robot" read as that planner's, which never arrived (a new user's run)
    last = dataclasses.replace(late, reached_t_s=10.01)  # --no-finish: reached in the state the loop overslept into
    assert not [ln for ln in _closing_lines(dataclasses.replace(cfg, finish=False), last) if ln.startswith("note: ")]
    for quiet in (dataclasses.replace(cfg, mode="lockstep"), cfg):  # lock-step finishes its plan; reached: nothing
        if quiet is cfg:
            summary = dataclasses.replace(summary, reached=True)
        assert not [ln for ln in _closing_lines(quiet, summary) if ln.startswith("note: a real-time run")]
    guarded = dataclasses.replace(summary, reached=False, separation_held_s=6.2, separation_at_end=True)
    note = [ln for ln in _closing_lines(cfg, guarded) if ln.startswith("note: ")]  # more time would not have helped
    assert len(note) == 1 and "the separation guard held it at the end (6.2 s" in note[0] and "--steps" not in note[0]
    once = dataclasses.replace(guarded, separation_held_s=0.02, separation_at_end=False)  # a hold on the way: the
    note = [ln for ln in _closing_lines(cfg, once) if ln.startswith("note: ")]  # time ran out (it blamed the guard)
    assert len(note) == 1 and "--steps 40" in note[0]


def test_the_services_log_at_debug_with_the_demos_debug_or_their_own_variable(monkeypatch) -> None:
    """The demo passed --log-level INFO to every service: neither `--log-level DEBUG` nor
    FORESIGHT_PLANNER_LOG_LEVEL=DEBUG reached the planner's per-plan lines (a flag beats the variable)."""
    from pathlib import Path

    from services.demo import DemoConfig
    from services.demo_services import service_args

    def levels(**kw: str) -> dict[str, str | None]:
        args = service_args(DemoConfig(**kw), "tcp/127.0.0.1:7447", Path("m.npz"), Path("h.npz"), 5, Path("r.mcap"))
        return {name: a[a.index("--log-level") + 1] if "--log-level" in a else None for name, a in args.items()}

    monkeypatch.delenv("FORESIGHT_PLANNER_LOG_LEVEL", raising=False)
    assert set(levels().values()) == {"INFO"}
    assert set(levels(log_level="DEBUG").values()) == {"DEBUG"}
    monkeypatch.setenv("FORESIGHT_PLANNER_LOG_LEVEL", "DEBUG")
    got = levels()
    assert got.pop("planner") is None and set(got.values()) == {"INFO"}  # the variable decides the planner's


def test_what_the_demo_sets_on_its_services_is_refused_from_their_file_or_variables(tmp_path: Path, monkeypatch,
                                                                                     capsys) -> None:
    """``[replayer] rate_hz = 10`` in the demo's config file gave a replayer at the demo's 30 Hz, and
    ``FORESIGHT_ZENOH_CONNECT`` was overridden by the demo's router: a flag beats both, without a word."""
    from services.demo import DemoConfig
    from services.demo_inputs import share_config_file
    from services.demo_services import demo_set_options

    monkeypatch.setenv("FORESIGHT_CONFIG", "")  # recorded as unset: whatever the demo sets, the test's end unsets
    monkeypatch.delenv("FORESIGHT_CONFIG")
    sets = {section: {o.name for o in options} for section, options in demo_set_options(DemoConfig()).items()}
    assert {"replayer.samples_per_tick", "planner.seed", "executor.steps", "zenoh.connect"} <= set().union(
        *sets.values())
    assert "replayer.rate_hz" not in sets["replayer"]  # each mode's own pace option only: the replayer says others
    realtime = DemoConfig(mode="realtime")
    assert "replayer.rate_hz" in {o.name for o in demo_set_options(realtime)["replayer"]}
    assert "tracker" not in sets and "planner.cost.w_human" not in sets["planner"]  # not run / not set by default
    assert "planner.cost.w_human" in {o.name for o in demo_set_options(DemoConfig(human_cost=False))["planner"]}
    conf = tmp_path / "c.toml"
    conf.write_text("[replayer]\nrate_hz = 10\n[planner]\nlog_level = 'DEBUG'\n[zenoh]\nconnect_timeout_s = 5\n")
    with pytest.raises(ConfigError, match=re.escape(f"replayer.rate_hz in {conf} (the demo's --rate-hz): foresight "
                                                    "demo sets this on its services' command lines")):
        share_config_file(str(conf), realtime)
    conf.write_text("[planner]\nlog_level = 'DEBUG'\n[zenoh]\nconnect_timeout_s = 5\n")  # what it leaves alone
    share_config_file(str(conf), DemoConfig())
    monkeypatch.setenv("FORESIGHT_ZENOH_CONNECT", "tcp/127.0.0.1:7447")
    monkeypatch.setenv("FORESIGHT_ZENOH_PREFIX", "lab")
    with pytest.raises(SystemExit) as e:
        main(["--run-dir", str(tmp_path / "run")])
    assert e.value.code == 2 and "$FORESIGHT_ZENOH_CONNECT; $FORESIGHT_ZENOH_PREFIX (the demo's --prefix): " \
        in capsys.readouterr().err and not (tmp_path / "run").exists()


def test_a_services_log_level_in_the_demos_config_file_is_its_own(tmp_path: Path, monkeypatch) -> None:
    """The file's ``[planner] log_level`` was beaten by the demo's ``--log-level INFO``, as the variable was."""
    from services.demo import DemoConfig
    from services.demo_services import service_args

    conf = tmp_path / "c.toml"
    conf.write_text("[planner]\nlog_level = 'DEBUG'\n")
    monkeypatch.setenv("FORESIGHT_CONFIG", str(conf))
    monkeypatch.delenv("FORESIGHT_PLANNER_LOG_LEVEL", raising=False)
    args = service_args(DemoConfig(), "tcp/127.0.0.1:7447", Path("m.npz"), Path("h.npz"), 5, Path("r.mcap"))
    assert "--log-level" not in args["planner"] and args["predictor"][-2:] == ["--log-level", "INFO"]


def test_the_demos_help_loads_neither_torch_nor_matplotlib() -> None:
    """`foresight demo --help` took 10 s: the demo module imported the run's modules (torch, the planner's compiler,
    matplotlib) to show its options. They are imported when a run starts."""
    code = ("import sys; from services.demo import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('torch', 'matplotlib', 'sklearn') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2]).stdout
    assert "usage: foresight demo" in out and out.strip().splitlines()[-1] == "[]", out[-500:]


def test_the_figure_title_gives_a_real_time_runs_wall_time_and_plans() -> None:
    """A real-time run's PNG said "20 steps of 0.5 s" over a lane of 100 plans."""
    import types

    from services.demo import DemoConfig
    from services.demo_figure import figure_title

    summary = types.SimpleNamespace(human_class="blue_cup", chosen_goal_per_step=["red_cup"] * 97, reached_t_s=None)
    lock = figure_title(DemoConfig(mode="lockstep"), summary, "pr2_two_cups_side")
    real = figure_title(DemoConfig(mode="realtime"), summary, "pr2_two_cups_side", "prediction interrupted")
    assert lock.endswith(f"{DemoConfig().steps} steps of {DemoConfig().period_s:g} s")
    wall = DemoConfig().steps * DemoConfig().period_s
    assert f"{wall:g} s in real time, 97 plans: the prediction interrupted" in real
    assert "steps of" not in real
    summary.reached_t_s = 14.62  # it went on after its 10 s (finish_s)
    assert f"{wall:g} s in real time, then on to its goal at 14.6 s, 97 plans" in figure_title(
        DemoConfig(mode="realtime"), summary, "pr2_two_cups_side")
    summary.reached_t_s = wall + 0.01  # --no-finish: the last state, overslept
    assert "then on" not in figure_title(DemoConfig(mode="realtime", finish=False), summary, "pr2_two_cups_side")
    summary.reached_t_s = 14.62
    assert "97 plans (the prediction planner's)" in figure_title(DemoConfig(mode="realtime", compare=True), summary,
                                                                 "pr2_two_cups_side")


@pytest.mark.parametrize("human_cost", [True, False])
def test_no_human_cost_is_a_planner_that_ignores_the_person_entirely(human_cost: bool) -> None:
    """``--human-cost false`` (the paper's basic STOMP, ``--compare``'s third planner): neither the predicted occupancy
    nor, in real time, the body as last seen (``services.planner.body``) costs anything."""
    import argparse

    from services.demo_services import service_options
    from services.planner.config import CostConfig, PlannerServiceConfig
    from shared.config import add_config_arguments, resolve_config

    flags = service_options(DemoConfig(mode="realtime", human_cost=human_cost), Path("m.npz"), Path("h.npz"), 3,
                            None)["planner"]
    parser = argparse.ArgumentParser()
    add_config_arguments(parser, "planner", PlannerServiceConfig)
    cfg, _ = resolve_config("planner", PlannerServiceConfig, parser.parse_args(flags), env={})
    cost = cfg.planner_config().cost
    assert (cost.w_human, cost.body_clearance) == ((CostConfig.w_human, CostConfig.body_clearance) if human_cost
                                                   else (0.0, 0.0))


def test_a_run_interrupted_before_its_first_plan_ends_naming_its_directory(tmp_path: Path, monkeypatch) -> None:
    """A new user's Ctrl-C as the services started: the run's directory kept its services' logs, `latest` went back
    to the run before, and the demo's last line named neither."""
    import threading

    import services.demo as demo
    import services.demo_run as demo_run
    from services.demo_dirs import RunDirectory

    root = tmp_path / "runs"
    before = RunDirectory.create(root, "lockstep", False)
    before.point_latest()
    (before.path / "before.mcap").write_bytes(b"a log")

    def run_once(cfg, name, stop, out, started=None):  # the services started, then the Ctrl-C; no MCAP yet
        started()
        (Path(cfg.run_dir) / "planner.log").write_text("started\n")
        return 130, None

    monkeypatch.setattr(demo_run, "run_once", run_once)
    said: list[str] = []
    assert demo.run_demo(DemoConfig(run_dir=root), threading.Event(), out=said.append) == (130, None)
    (run,) = [p for p in root.iterdir() if p.name not in ("latest", before.path.name)]
    assert said == [f"foresight demo: this run's files: {run}/: its services' logs, no MCAP log (the executor had not "
                    f"opened one); {root / 'latest'} still points to {before.path.name}, the run before (a run "
                    "without an MCAP log hands it back)"]
    assert (root / "latest").resolve() == before.path.resolve()


def test_an_interrupted_runs_closing_lines_say_whether_its_log_was_finalised(tmp_path: Path) -> None:
    from services.demo_closing import closing_lines as _closing_lines
    from services.scenario import Summary
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    mcap = tmp_path / "run.mcap"
    with McapLog(mcap, Keys()):
        pass
    summary = Summary(steps=[], chosen_goal_per_step=[], switch_step=None, interference_cost=0.0, mcap_path=str(mcap),
                      reached=False, reached_step=None, human_class="blue_cup", recognised_class="blue_cup",
                      extra={"run_dir": str(tmp_path), "cut_short": "interrupted after 3 of 20 steps"})
    assert f"MCAP log: {mcap} (complete)" in _closing_lines(DemoConfig(), summary, interrupted=True)
    mcap.write_bytes(mcap.read_bytes()[:-30])
    assert any(ln.startswith(f"MCAP log: {mcap} (TRUNCATED (") for ln in _closing_lines(DemoConfig(), summary, True))
    # not interrupted: a log that is not complete says so all the same (a full disk lost half of one without a word)
    assert any(ln.startswith(f"MCAP log: {mcap} — INCOMPLETE: TRUNCATED (") for ln in _closing_lines(DemoConfig(),
                                                                                                    summary))


def test_a_whole_runs_closing_line_says_when_a_full_disk_cut_its_log_short(tmp_path: Path) -> None:
    from services.demo_closing import closing_lines as _closing_lines
    from services.scenario import Summary
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    mcap = tmp_path / "run.mcap"
    with McapLog(mcap, Keys()):
        pass
    summary = Summary(steps=[], chosen_goal_per_step=[], switch_step=None, interference_cost=0.0, mcap_path=str(mcap),
                      reached=True, reached_step=3, human_class="blue_cup", recognised_class="blue_cup",
                      extra={"run_dir": str(tmp_path)})
    assert f"MCAP log: {mcap}" in _closing_lines(DemoConfig(), summary)  # complete: the path alone
    summary.extra["log_incomplete"] = (f"{mcap}: INCOMPLETE: 582 of 1164 messages written (No space left on device: "
                                       "1687437 bytes refused for 3 s)")
    assert (f"MCAP log: {mcap} — INCOMPLETE: 582 of 1164 messages written (No space left on device: 1687437 bytes "
            "refused for 3 s)") in _closing_lines(DemoConfig(), summary)


STOPPING_DEMO = """
import sys, threading, time
from pathlib import Path
import services.demo as demo

def run_demo(cfg, stop, out=print, on_start=lambda run: None):  # the services started, then stop one by one, slowly
    on_start(Path(sys.argv[1]) / "run")
    print("ready", flush=True)
    stop.wait(30)
    time.sleep(30)
    return 130, None

demo.run_demo = run_demo
sys.exit(demo.main(["--run-dir", sys.argv[1]]))
"""


def test_a_second_ctrl_c_while_the_demo_stops_names_the_runs_directory(tmp_path: Path, signalled) -> None:
    """A new user's second Ctrl-C as `make demo` stopped ended with "second SIGINT while stopping; exiting with status
    3" and make's "Error 3": no line said where the run was, nor that its MCAP log (complete) was being finished."""
    import signal

    end = signalled(["-c", STOPPING_DEMO, str(tmp_path)], [(signal.SIGINT, 0.0), (signal.SIGINT, 0.5)], timeout=30)
    run = tmp_path / "run"
    assert end.returncode == 3, end.stderr[-2000:]
    assert end.stderr.splitlines()[-1] == (
        f"foresight demo: second SIGINT while stopping; exiting with status 3; this run's files: {run}/; its services "
        f"stop on their own (each sees the demo gone) and the executor finishes the MCAP log: check it with "
        f"`foresight log info {run}`"), end.stderr[-2000:]
