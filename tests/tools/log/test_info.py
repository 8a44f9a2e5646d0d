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
