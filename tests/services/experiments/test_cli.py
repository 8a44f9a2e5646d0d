"""`foresight eval interference|switch`: counts and seeds out of range are one line, before any model is trained."""

from __future__ import annotations

import pytest

from services.experiments.cli import main


@pytest.mark.parametrize(("argv", "message"), [
    (["interference", "--demos", "-1"], "--demos and --seeds must be >= 1, got -1 and 10"),
    (["interference", "--demos", "0"], "--demos and --seeds must be >= 1, got 0 and 10"),
    (["interference", "--seeds", "0"], "--demos and --seeds must be >= 1, got 5 and 0"),
    (["switch", "--demos", "-3"], "--demos must be >= 0 (0: all) and --seed >= 0, got -3 and 0"),
    (["switch", "--seed", "-1"], "--demos must be >= 0 (0: all) and --seed >= 0, got 0 and -1"),
])
def test_counts_and_seeds_out_of_range_are_one_line(tmp_path, capsys, argv, message) -> None:
    """They were a numpy traceback, a table of NaN, every demonstration, or a minute's stall per failed step."""
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--models-dir", str(tmp_path / "models"), "--work-dir", str(tmp_path / "work")])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "models").exists()  # refused before training


@pytest.mark.parametrize("argv", [["--help"], ["interference", "--help"], ["all", "--help"], ["pace", "--help"]])
def test_the_experiments_help_loads_no_torch(argv) -> None:
    """`foresight eval --help` took 12 s: the parser imported every experiment (the services, torch) for its defaults
    and the modules' docstrings. The defaults live in protocol.py and planners.py, the docstrings are read from the
    source, the experiments are imported to run."""
    import subprocess
    import sys
    from pathlib import Path

    code = (f"import sys\nfrom services.experiments.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n"
            "    pass\nprint('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[3]).stdout
    assert "usage: foresight eval" in out and out.strip().splitlines()[-1] == "False", out[-500:]


@pytest.mark.parametrize("argv", [["switch", "--plot", "{f}/fig9.png"], ["pace", "--plot", "{f}/pace.png"],
                                  ["occupancy", "--out", "{f}"], ["recognition", "--plot", "{f}/r.png"],
                                  ["recognition", "--calibration-plot", "{f}/c.png"]])
def test_an_output_path_a_file_is_in_the_way_of_is_refused_before_the_work(tmp_path, capsys, argv) -> None:
    """It was refused after every run ('File exists'), the results lost and the table never printed."""
    afile = tmp_path / "afile"
    afile.write_text("")
    argv = [a.format(f=afile) for a in argv]
    extra = [] if argv[0] in ("recognition", "occupancy") else ["--models-dir", str(tmp_path / "models"),
                                                                 "--work-dir", str(tmp_path / "work")]
    with pytest.raises(SystemExit) as stop:
        main([*argv, *extra])
    out, err = capsys.readouterr()
    assert stop.value.code == 2 and err.strip().splitlines() == [
        f"foresight eval {argv[0]}: error: {afile}: a file is in the way (a directory is needed there)"]
    assert not out and not (tmp_path / "models").exists() and not (tmp_path / "work").exists()  # no work done


@pytest.mark.parametrize(("argv", "message"), [
    (["occupancy", "--resolution", "-1"], "--resolution must be between 0.005 and 0.5 m, got -1.0"),
    (["occupancy", "--resolution", "0.001"], "--resolution must be between 0.005 and 0.5 m, got 0.001"),
    (["pace", "--libraries", "synthetic,{tmp}/none"], "{tmp}/none"),
    (["switch", "--plot", "{tmp}/fig9.jpg"], "--plot"),  # it ran the experiment, then matplotlib refused jpg
    (["pace", "--plot", "{tmp}/pace"], "--plot"),  # written pace.png, said pace
])
def test_bad_inputs_are_refused_before_any_work(tmp_path, capsys, argv, message) -> None:
    """-1 was a joblib traceback and 0.001 a 43 GiB allocation after the demonstrations' sweep; a missing library
    of `eval pace` was said after the other libraries' runs."""
    with pytest.raises(SystemExit) as stop:
        main([*(a.format(tmp=tmp_path) for a in argv), "--out" if argv[0] == "occupancy" else "--work-dir",
              str(tmp_path / "work"), *(["--models-dir", str(tmp_path / "models")] if argv[0] != "occupancy" else [])])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1 and message.format(tmp=tmp_path) in err[0], err
    assert not (tmp_path / "models").exists() and not (tmp_path / "work").exists()


def test_recognition_with_no_workers_is_one_line(capsys) -> None:
    """joblib's 'n_jobs == 0 in Parallel has no meaning' came as a traceback, after the library was read."""
    with pytest.raises(SystemExit) as stop:
        main(["recognition", "--n-jobs", "0"])
    assert stop.value.code == 2 and "--n-jobs: 0 runs nothing" in capsys.readouterr().err



@pytest.mark.parametrize(("argv", "message"), [
    (["interference", "--rollouts", "3"], "--reuse must be below --rollouts (the best rollouts kept for the next "
     "iteration), got --rollouts 3 and --reuse 5 (its default, the planner's)"),
    (["switch", "--protocol", "paper", "--rollouts", "5"], "got --rollouts 5 and --reuse 5 (its default, the paper "
     "protocol's)"),
    (["interference", "--reuse", "10"], "got --rollouts 10 (its default, the planner's) and --reuse 10"),
    (["interference", "--rollouts", "2000"], "--rollouts must be in [2, 1024] and --reuse >= 0, got 2000 and None"),
    (["interference", "--period-s", "inf"], "--period-s must be in [0.001, 60] s (a clock tick's period), got inf"),
    (["switch", "--period-s", "120"], "--period-s must be in [0.001, 60] s (a clock tick's period), got 120.0"),
])
def test_stomp_and_period_options_are_checked_by_their_names_before_any_training(tmp_path, capsys, argv,
                                                                                message) -> None:
    """``--rollouts 3`` failed after the models' training as "planner.stomp.reuse must be in [0, rollouts - 1 = 2],
    got 5", an option never given; ``--period-s inf`` and ``120`` as executor.step_period_s, minutes in."""
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--models-dir", str(tmp_path / "models"), "--work-dir", str(tmp_path / "work")])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "models").exists() and not (tmp_path / "work").exists()
