"""The summary of a log: a truncated file says so and still lists what was written."""

from __future__ import annotations

from shared.recording.reader import read_log
from tools.log.info import format_info


def test_info_on_a_truncated_file(run_log, tmp_path) -> None:
    data = run_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) - 300])  # footer and part of the summary gone
    lf = read_log(cut)
    assert not lf.complete
    assert "TRUNCATED" in format_info(lf)
    text = format_info(lf)
    # one count of messages in both lines: the refused payloads (on /foresight/rejected) apart in each
    messages = int(text.split("messages:  ")[1].split()[0])
    refused = lf.channels and sum(c.count for c in lf.channels.values() if c.topic == "/foresight/rejected")
    assert refused and messages + refused == lf.message_count and messages > 0
    assert f"recovered {messages} messages and {refused} refused payloads" in text
    assert lf.channels  # what was written before is still listed


def test_info_counts_the_foxglove_updates(run_log) -> None:
    """A log whose Foxglove updates were built on the writer's thread says how many were dropped."""
    text = format_info(read_log(run_log))
    assert "foxglove:  dropped 0, unfinished 0, errors 0" in text


def test_info_of_a_log_without_messages(tmp_path, capsys) -> None:
    """An empty log: no 'time: None .. None'."""
    from shared.protocol import Keys
    from shared.recording.writer import McapLog
    from tools.log.cli import main

    path = tmp_path / "empty.mcap"
    McapLog(path, Keys()).close()
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "time:      -" in out and "None" not in out


def test_latency_json_is_strict_json_when_a_series_is_empty(monkeypatch, capsys) -> None:
    """A series without samples (no occupancy in the log, say) printed NaN, which strict JSON parsers refuse."""
    import json

    import tools.log.cli as cli
    from shared.recording.reader import LogFile
    from tools.log.latency import Stat

    def latencies(path, read, samples=None):
        read.append(LogFile(str(path), 0, complete=True))
        return {"pose_to_plan": Stat.of([4.5]), "occupancy_to_plan": Stat.of([])}

    monkeypatch.setattr(cli, "log_latencies", latencies)
    assert cli.main(["latency", "any.mcap", "--json"]) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    assert out["occupancy_to_plan"]["count"] == 0 and out["occupancy_to_plan"]["p50"] is None
    assert out["pose_to_plan"]["p50"] == 4.5 and out["complete"] is True


def _run(tmp_path, mode: str, seconds: float, ticks: int = 0):
    """A log of ``mode`` with 20 steps of 0.5 s configured and ``seconds`` of states (real time) or ``ticks`` ticks."""
    import numpy as np

    from shared.protocol import ClockTick, Keys, RobotState, encode
    from shared.recording.writer import McapLog

    keys, t0, now = Keys(), 1_700_000_000.0, [0.0]
    path = tmp_path / f"{mode}-{seconds}.mcap"
    log = McapLog(path, keys, None, clock=lambda: int((t0 + now[0]) * 1e9),
                  run_metadata={"mode": mode, "steps": "20", "step_period_s": "0.5", "state_rate_hz": "50.0",
                                "stop_on_goal": "False", "prefix": "foresight"})
    for k in range(round(seconds * 50)):  # the first state a state period into the run
        now[0] = 0.02 * (k + 1)
        log.on_sample(keys.robot_state, encode(RobotState(stamp=t0 + now[0], tick=-1, joint_names=["a"], goal=0,
                                                          reached=False, holding=False, reason="", q=np.zeros(1),
                                                          qd=np.zeros(1))))
    for n in range(ticks):
        log.on_sample(keys.clock, encode(ClockTick(stamp=0.5 * n, tick=n, period=0.5)))
    log.close()
    return read_log(path)


def test_info_says_how_many_of_its_steps_an_interrupted_run_ran(tmp_path) -> None:
    """An interrupted run's log is complete too: `log info` said `steps=20 ... complete` of a run cut after 2."""
    from tools.log.info import info_dict

    assert "\nran:       2 of 20 steps (interrupted)" in format_info(_run(tmp_path, "realtime", 1.2))
    whole = _run(tmp_path, "realtime", 10.0)
    assert "\nran:       20 of 20 steps\n" in format_info(whole) + "\n"
    assert info_dict(whole)["ran"] == {"steps": 20, "of": 20, "interrupted": False, "more_s": 0.0}
    assert "\nran:       20 of 20 steps, and 1.4 s more (finish_s" in format_info(_run(tmp_path, "realtime", 11.4))
    assert "\nran:       3 of 20 steps (interrupted)" in format_info(_run(tmp_path, "lockstep", 0.0, ticks=3))
