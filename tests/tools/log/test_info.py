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
    assert f"recovered {lf.message_count} messages" in format_info(lf) and lf.message_count > 0
    assert lf.channels  # what was written before is still listed


def test_info_counts_the_foxglove_updates(run_log) -> None:
    """A log whose Foxglove updates were built on the writer's thread says how many were dropped."""
    text = format_info(read_log(run_log))
    assert "foxglove:  dropped 0, unfinished 0, errors 0" in text
