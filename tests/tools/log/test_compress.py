"""``foresight log compress``: the same log with compressed chunks, read back identical."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from shared.recording.reader import read_log
from shared.runtime import UserError
from tools.log.cli import main
from tools.log.compress import compress_log, same_messages


def test_round_trip_is_identical_and_sizes_follow_the_compression(run_log: Path, tmp_path: Path) -> None:
    plain = compress_log(run_log, tmp_path / "plain.mcap", "none")
    packed = compress_log(tmp_path / "plain.mcap", tmp_path / "packed.mcap", "zstd")
    assert plain.identical and packed.identical and plain.input_complete
    assert plain.messages == packed.messages == read_log(run_log).message_count
    assert packed.size_out < plain.size_out
    assert "x smaller" in packed.line(Path("a"), Path("b")) and "x larger" in plain.line(Path("a"), Path("b"))
    assert same_messages(run_log, tmp_path / "packed.mcap")
    assert read_log(tmp_path / "packed.mcap").complete



def test_a_changed_payload_or_a_missing_last_message_is_a_difference(run_log: Path, tmp_path: Path) -> None:
    """Compared one message at a time (it held both logs' payloads in two lists: 701 MB for 300 x 1 MiB)."""
    from mcap.writer import Writer

    from shared.recording.reader import iter_messages

    messages = list(iter_messages(run_log))
    lf = read_log(run_log)

    def copy(path: Path, drop_last: bool = False, flip: int | None = None) -> Path:
        with path.open("wb") as f:
            w = Writer(f)
            w.start(profile=lf.profile, library=lf.library)
            ids = {}
            for c in lf.channels.values():
                sid = w.register_schema(c.schema_name, c.schema_encoding, b"{}") if c.schema_name else 0
                ids[c.topic] = w.register_channel(c.topic, c.message_encoding, sid)
            for i, m in enumerate(messages[:-1] if drop_last else messages):
                data = bytes([m.data[0] ^ 1]) + m.data[1:] if i == flip else m.data
                w.add_message(ids[m.topic], m.log_time, data, m.publish_time)
            for name, data in lf.attachments.items():
                w.add_attachment(0, 0, name, "application/octet-stream", data)
            for name, meta in lf.metadata.items():
                w.add_metadata(name, meta)
            w.finish()
        return path

    assert same_messages(run_log, copy(tmp_path / "same.mcap"))
    assert not same_messages(run_log, copy(tmp_path / "flipped.mcap", flip=len(messages) // 2))
    assert not same_messages(run_log, copy(tmp_path / "short.mcap", drop_last=True))

def test_truncated_input_is_copied_up_to_its_last_chunk(run_log: Path, tmp_path: Path) -> None:
    compress_log(run_log, tmp_path / "plain.mcap", "none", chunk_size=4096)
    data = (tmp_path / "plain.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    result = compress_log(cut, tmp_path / "out.mcap")
    assert not result.input_complete and result.identical
    assert 0 < result.messages == read_log(cut).message_count
    assert "truncated" in result.line(cut, tmp_path / "out.mcap")


def test_cli_and_bad_input(run_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compress", str(run_log), str(tmp_path / "o.mcap"), "--compression", "lz4"]) == 0
    assert "read back identical" in capsys.readouterr().out
    with pytest.raises(UserError, match="not found"):
        compress_log(tmp_path / "missing.mcap", tmp_path / "o2.mcap")
    shutil.copy(run_log, tmp_path / "same.mcap")
    with pytest.raises(UserError, match="another file"):
        compress_log(tmp_path / "same.mcap", tmp_path / "same.mcap")
    (tmp_path / "text.mcap").write_text("not a log")
    with pytest.raises(SystemExit) as e:
        main(["compress", str(tmp_path / "text.mcap"), str(tmp_path / "o3.mcap")])
    assert e.value.code == 2 and "not an MCAP file" in capsys.readouterr().err


def test_a_pipe_as_the_output_is_refused_in_one_line_and_left_alone(run_log: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """`compress X /dev/null` as root replaced the device with a regular file (a FIFO stands in for it here)."""
    import os
    import stat

    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    with pytest.raises(SystemExit) as e:
        main(["compress", str(run_log), str(fifo)])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and f"{fifo}: a named pipe (FIFO) is there, not a regular file" in err[0]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and sorted(p.name for p in tmp_path.iterdir()) == ["pipe.mcap"]


def test_a_log_still_being_written_is_copied_so_far_and_compared_with_what_it_had(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A run's log read while the run goes on grew between the copy and the comparison: "NOT IDENTICAL", exit 1,
    though the copy was right, and `info` said TRUNCATED (a review)."""
    import tools.log.compress as compress
    from shared.protocol import ClockTick, Keys, encode
    from shared.recording.writer import McapLog
    from tools.log.info import format_info

    keys = Keys()
    src, dst = tmp_path / "live.mcap", tmp_path / "copy.mcap"
    live = McapLog(src, keys, None, chunk_size=1024, flush_period_s=60.0)
    ticks = iter(range(10 ** 6))

    def more(n: int) -> None:
        for _ in range(n):
            i = next(ticks)
            live.on_sample(keys.clock, encode(ClockTick(stamp=0.1 * i, tick=i, period=0.1)))
        live.flush()

    copy = compress._copy

    def copy_while_the_run_goes_on(*args, **kwargs):
        out = copy(*args, **kwargs)
        more(30)  # the run's next messages, written before the comparison reads the log again
        return out

    try:
        more(40)
        lf = read_log(src)
        assert lf.being_written and not lf.complete and "STILL BEING WRITTEN" in format_info(lf)
        assert "TRUNCATED" not in format_info(lf) and f"{lf.message_count} messages, " in format_info(lf)
        monkeypatch.setattr(compress, "_copy", copy_while_the_run_goes_on)
        assert main(["compress", str(src), str(dst)]) == 0
        out = capsys.readouterr().out
        copied = read_log(dst)
        assert copied.complete and copied.message_count == lf.message_count == 40
        assert "still being written (a run holds its lock): 40 messages copied so far" in out
        assert "compared identical with the log's first 40" in out and "NOT IDENTICAL" not in out
        assert copied.metadata["foresight.compress"]["source_error"].startswith("still being written")
        assert "complete; copied from a log still being written" in format_info(copied)
    finally:
        live.close()
    assert not read_log(src).being_written and read_log(src).complete
