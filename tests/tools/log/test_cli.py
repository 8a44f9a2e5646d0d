"""``foresight log info / render``: what they print and draw, and one-line errors."""

from __future__ import annotations

import json

import pytest

from shared.protocol import Keys
from tools.log.cli import main

KEYS = Keys()


def test_info_lists_channels_schemas_and_counts(run_log, capsys) -> None:
    assert main(["info", str(run_log)]) == 0
    out = capsys.readouterr().out
    assert "complete" in out and "TRUNCATED" not in out
    lines = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith("  ") and "/" in ln}
    assert lines[KEYS.plan][1:] == ["foresight.Plan", "jsonschema", "msgpack", "2"]
    assert lines[KEYS.robot_state][-1] == "2" and lines[KEYS.occupancy][-1] == "2"
    assert lines["/viz/plan"][1:] == ["foxglove.SceneUpdate", "protobuf", "protobuf", "2"]
    assert lines["/foresight/rejected"][-1] == "1"
    assert "scene.toml" in out and f"rejected:  {KEYS.plan}: 1" in out and "mode=lockstep" in out
    assert main(["info", str(run_log), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["complete"] and d["rejected"] == {KEYS.plan: 1}
    assert {c["topic"]: c["messages"] for c in d["channels"]}[KEYS.clock] == 2


def test_info_does_not_count_refused_payloads_as_data(run_log, capsys) -> None:
    assert main(["info", str(run_log), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    data = sum(c["messages"] for c in d["channels"] if c["topic"] != "/foresight/rejected")
    assert d["messages"] == data and d["rejected_records"] == 1
    assert d["rejected_reasons"] == {f"{KEYS.plan} malformed": 1}
    assert main(["info", str(run_log)]) == 0
    out = capsys.readouterr().out
    assert f"messages:  {data} on " in out and "(and 1 refused payloads on /foresight/rejected, not counted)" in out
    assert f"by reason: {KEYS.plan} malformed: 1" in out


def test_render_writes_pngs(run_log, tmp_path, capsys) -> None:
    out = tmp_path / "step1.png"
    assert main(["render", str(run_log), "--step", "1", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    import matplotlib.image as mpimg

    img = mpimg.imread(out)
    assert img.shape[0] > 500 and img.shape[1] > 1000
    assert main(["render", str(run_log), "--all", "--out", str(tmp_path / "all")]) == 0
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["step_000.png", "step_001.png"]
    with pytest.raises(SystemExit):  # --step was ignored without a word beside --all, and every step drawn
        main(["render", str(run_log), "--step", "1", "--all", "--out", str(tmp_path / "both")])
    assert "give --step N or --all, not both" in capsys.readouterr().err and not (tmp_path / "both").exists()


def test_info_of_a_directory_describes_every_log_under_it(run_log, tmp_path, capsys) -> None:
    """After `demo --compare` the README's `log info runs/demo/latest/*.mcap` found nothing (each planner's run has its
    own directory) and `log info runs/demo/latest` only listed the logs."""
    import shutil

    for name in ("prediction", "current-occupancy"):
        (tmp_path / name).mkdir()
        shutil.copy(run_log, tmp_path / name / f"{name}.mcap")
    assert main(["info", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.count("complete") == 2 and "prediction.mcap" in out and "current-occupancy.mcap" in out
    assert main(["info", str(tmp_path), "--json"]) == 0
    assert [d["complete"] for d in json.loads(capsys.readouterr().out)] == [True, True]
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit):
        main(["info", str(tmp_path / "empty")])
    assert "no .mcap file under it" in capsys.readouterr().err
    (tmp_path / "empty" / "broken.mcap").write_bytes(b"")  # one unreadable log: named, the others still described
    assert main(["info", str(tmp_path)]) == 1  # not a success (it was 0)
    out = capsys.readouterr().out
    assert out.count("complete") == 2 and "broken.mcap: " in out and "not an MCAP file (empty)" in out
    broken = str(tmp_path / "empty" / "broken.mcap")
    assert f"file: {broken}: not an MCAP" in out and f"{broken}: {broken}" not in out  # the path once
    assert main(["info", str(tmp_path), "--json"]) == 1
    assert [("unreadable" in d) for d in json.loads(capsys.readouterr().out)] == [False, True, False]
    assert main(["info", str(tmp_path / "empty")]) == 2  # none readable


def test_the_other_commands_read_a_compare_runs_prediction_log_and_say_so(run_log, tmp_path, capsys) -> None:
    """The README's `log table runs/demo/latest` (and latency, snapshot, render) after `demo --compare` said only that
    the path is a directory of three logs (a new user's run)."""
    import shutil

    for name in ("prediction", "current-occupancy", "no-human-cost"):
        (tmp_path / name).mkdir()
        shutil.copy(run_log, tmp_path / name / f"{name}.mcap")
    assert main(["table", str(tmp_path), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["complete"]
    main_log = tmp_path / "prediction" / "prediction.mcap"
    assert f"{tmp_path} is a demo --compare run: its prediction run's log, {main_log}" in captured.err
    assert main(["latency", str(tmp_path)]) == 0 and "prediction.mcap" in capsys.readouterr().err
    shutil.rmtree(tmp_path / "prediction")  # two logs, neither the prediction run's: which one is not guessed
    with pytest.raises(SystemExit):
        main(["table", str(tmp_path)])
    assert "is a directory; the logs under it" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["info", "/nonexistent.mcap"], "not found"),
    (["render", "{log}", "--step", "7", "--out", "x.png"], "no plan for step 7"),
    (["render", "{log}", "--out", "x.png"], "--step N or --all"),
    (["render", "{log}", "--step", "1", "--out", "{tmp}/step1"], "ending in .png"),  # it wrote step1.png, said step1
    (["info", "{bad}"], "not an MCAP file"),
    (["render", "{log}", "--all", "--out", ""], "argument --out: empty"),  # its PNGs went into the working directory
    (["render", "{log}", "--all", "--out", "{bad}"], "a file; with --all, --out is the directory"),  # 'File exists'
    (["snapshot", "{log}", "--out", " "], "argument --out: empty"),
    (["compress", "{log}", ""], "argument out: empty"),
])
def test_errors_are_one_line(run_log, tmp_path, capsys, argv, message) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"hello, this is not mcap at all")
    argv = [a.format(log=run_log, bad=bad, tmp=tmp_path) for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and err[0].startswith(f"foresight log {argv[0]}: error: ")
    assert not list(tmp_path.glob("step1*"))


def test_a_metadata_record_of_counts_that_is_not_is_a_warning_and_the_rest_is_shown(tmp_path, capsys) -> None:
    """Another tool's record under our metadata name made `info` refuse the whole file (a traceback, then one line)."""
    from mcap.writer import Writer

    odd = tmp_path / "odd.mcap"
    with odd.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="other", library="other-tool")
        writer.add_metadata("foresight.rejects", {"k": "many", "foresight/planner/plan": "3"})
        writer.finish()
    assert main(["info", str(odd)]) == 0
    out = capsys.readouterr().out
    assert "profile:   other   library: other-tool" in out and "rejected:  foresight/planner/plan: 3" in out
    assert "warning:   metadata 'foresight.rejects': 1 entry not counts, left out (not a Foresight log, or a damaged " \
           "one): {'k': 'many'}" in out
    assert main(["info", str(odd), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["rejected"] == {"foresight/planner/plan": 3} and len(d["warnings"]) == 1


def test_the_demos_interrupt_line_says_which_plans_the_log_has(run_log) -> None:
    """Ctrl-C mid-run: the live table printed a 64th plan made after the executor had closed its log, and the demo
    said "interrupted after 64 plans; log ...: complete" while the log held 63."""
    from services.demo_lines import log_phrase as _log_state

    assert _log_state(run_log, KEYS.plan, 2).endswith("complete, " + _log_state(run_log).split("complete, ")[1]
                                                     + ", 2 plans")
    assert _log_state(run_log, KEYS.plan, 3).endswith(", 2 plans (the last 1 came after the executor closed it)")
    assert "2 plans (1 after the rows above" in _log_state(run_log, KEYS.plan, 1)  # rows stop at Ctrl-C, the log not
    # real time: plans the executor never adopted are in the log, not in the summary or `log table` (it said
    # `log table` printed every one: 29 logged, 23 printed)
    assert _log_state(run_log, KEYS.plan, 0, 1).endswith(
        f"2 plans (2 after the rows above, made while the executor stopped; the summary and `foresight log table "
        f"{run_log}` count the 1 the executor adopted, the others were never executed)")
    assert _log_state(run_log, KEYS.plan, 0, 2).endswith(f": `foresight log table {run_log}` prints every one)")
    cut = run_log.parent / "cut.mcap"  # a killed executor never closed its log: its last plans were never in it
    data = run_log.read_bytes()
    cut.write_bytes(data[: len(data) - 200])
    assert _log_state(cut, KEYS.plan, 3).endswith("2 plans (the last 1 are not in it: it ends before them)")


@pytest.mark.parametrize("command", [["table"], ["render", "--all", "--out", "{tmp}/steps"]])
def test_plans_that_none_decode_are_named_not_said_missing(tmp_path, capsys, command) -> None:
    """Every Plan payload undecodable: 'table' said "no plans logged" and 'render' "no Plan messages in the log"."""
    from mcap.writer import Writer

    path = tmp_path / "plans.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="foresight", library="test")
        channel = writer.register_channel(KEYS.plan, "msgpack", writer.register_schema("foresight.Plan", "jsonschema",
                                                                                      b"{}"))
        for i in range(3):
            writer.add_message(channel, i, b"\x80", i)  # an empty map: no field of a Plan
        writer.finish()
    with pytest.raises(SystemExit) as exc:
        main([command[0], str(path), *(a.format(tmp=tmp_path) for a in command[1:])])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1
    assert f"{path}: 3 Plan message(s), none decodable (first error: " in err[0], err[0]


@pytest.mark.parametrize("argv", [["render", "{log}", "--step", "1", "--out", "{text}/x.png"],
                                  ["render", "{log}", "--all", "--out", "{text}/steps"],
                                  ["snapshot", "{log}", "--out", "{text}/x.png"]])
def test_a_file_in_the_way_of_the_output_s_directory_is_named(run_log, tmp_path, capsys, argv) -> None:
    """mkdir's own words: 'foresight log render: error: text.mcap: File exists' (a review)."""
    text = tmp_path / "text.mcap"
    text.write_text("notes")
    with pytest.raises(SystemExit) as exc:
        main([a.format(log=run_log, text=text) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1
    assert err[0] == f"foresight log {argv[0]}: error: {text}: a file is in the way (a directory is needed there)"
    assert text.read_text() == "notes"


def test_the_words_for_slowest_say_slowest_not_latest() -> None:
    """README and the module's docstring said `--slowest N` lists the N latest plans; it lists the N slowest."""
    from pathlib import Path

    import tools.log.cli as cli

    readme = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    said = [ln for ln in readme.splitlines() if "--slowest" in ln] + [
        ln for ln in (cli.__doc__ or "").split("* ") if "--slowest" in ln]
    assert said and all("latest plans" not in " ".join(ln.split()) and "slowest" in ln.replace("--slowest", "")
                        for ln in said), said
