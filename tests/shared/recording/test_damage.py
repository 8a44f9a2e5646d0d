"""A log survives a disk that is full for a while, and damage anywhere in a file is reported, never crashed on."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

import shared.recording.direct_file as direct_file
from shared.protocol import Keys
from shared.recording.reader import read_log
from shared.recording.writer import McapLog
from shared.runtime import UserError

from .conftest import sample_messages

KEYS = Keys()


def _full_disk_for(calls: range, monkeypatch) -> list[int]:
    """os.write in the log's file refuses the calls in ``calls`` (counted from 0) as a full disk does; the
    first of them writes half of what it is given before refusing the rest."""
    real, n = os.write, [0]

    def write(fd: int, data) -> int:
        i = n[0]
        n[0] += 1
        if i in calls:
            if i == calls.start and len(data) > 1:
                return real(fd, memoryview(data)[: len(data) // 2])  # part taken, the rest refused next call
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(direct_file.os, "write", write)
    return n


def _log(path: Path, pr2, rounds: int) -> list[tuple[str, bytes]]:
    log = McapLog(path, KEYS, None, chunk_size=2048, clock=iter(range(10**9, 2 * 10**9, 1000)).__next__)
    sent = []
    for _ in range(rounds):
        for key, payload in sample_messages(pr2):
            log.on_sample(key, payload)
            sent.append((key, payload))
    log.close()
    return sent


def test_a_disk_full_for_a_while_loses_nothing_once_space_returns(tmp_path, pr2, monkeypatch) -> None:
    """A refused write left half a chunk in the file: every reader stopped there, and all that came after was lost."""
    _full_disk_for(range(5, 25), monkeypatch)
    sent = _log(tmp_path / "run.mcap", pr2, rounds=30)
    lf = read_log(tmp_path / "run.mcap", keep=lambda ch: True)
    assert lf.complete and lf.error == ""
    assert [(m.topic, m.data) for m in lf.messages] == sent


def test_a_disk_that_stays_full_ends_the_log_where_it_stopped_and_close_is_not_repeated(tmp_path, pr2,
                                                                                       monkeypatch) -> None:
    monkeypatch.setattr(direct_file, "MAX_HELD_BYTES", 4096)
    _full_disk_for(range(5, 10**9), monkeypatch)
    log = McapLog(tmp_path / "run.mcap", KEYS, None, chunk_size=2048)
    outcomes = []
    for _ in range(30):
        for key, payload in sample_messages(pr2):
            try:
                log.on_sample(key, payload)
                outcomes.append("written")
            except OSError as exc:
                outcomes.append(str(exc))
    log.flush()  # nothing to write once the file has ended: the flush of a service's loop must not raise
    log.flush_if_due()
    with pytest.raises(OSError):
        log.close()
    log.close()  # once: nothing written again over the end it could not write
    first = next(i for i, o in enumerate(outcomes) if o != "written")
    # once the file has ended, every message is refused at once (the writer took them into an index of a chunk
    # it could never write, and only one in a chunk's worth of messages raised, so the caller counted few)
    assert all("the log has ended" in o for o in outcomes[first + 1:]) and len(outcomes) - first > 100
    lf = read_log(tmp_path / "run.mcap")
    assert not lf.complete and lf.error  # a truncated log, read up to where the disk stopped taking bytes


def test_damage_outside_the_chunks_is_reported(tmp_path, pr2) -> None:
    """The scene attachment and the metadata had no checksum: a flipped byte there read as a complete log."""
    path = tmp_path / "run.mcap"
    log = McapLog(path, KEYS, None, scene_text="name = 'scene'\n" * 20)
    for key, payload in sample_messages(pr2):
        log.on_sample(key, payload)
    log.close()
    data = bytearray(path.read_bytes())
    at = data.index(b"name = 'scene'") + 3
    data[at] ^= 0x20
    path.write_bytes(bytes(data))
    lf = read_log(path)
    assert not lf.complete and "CRC" in lf.error


def test_a_damaged_length_inside_a_record_is_damage_not_a_memory_error(tmp_path, pr2) -> None:
    path = tmp_path / "run.mcap"
    log = McapLog(path, KEYS, None, scene_text="name = 'scene'\n")
    log.close()
    data = bytearray(path.read_bytes())
    length_at = data.index(b"name = 'scene'") - 8  # the attachment's data length, just before its data
    for value in (2**40, 2**63 + 5):  # exabytes asked for; past an index-sized int
        data[length_at:length_at + 8] = value.to_bytes(8, "little")
        path.write_bytes(bytes(data))
        lf = read_log(path)
        assert not lf.complete and lf.error


@pytest.mark.parametrize("content", [b"", b"hi\n", b"{}\n", b"\x89MCAP0\r"])
def test_a_short_file_is_not_an_mcap_file(tmp_path, content) -> None:
    (tmp_path / "x.mcap").write_bytes(content)
    with pytest.raises(UserError, match="not an MCAP file"):
        read_log(tmp_path / "x.mcap")
    with pytest.raises(UserError, match="not an MCAP file"):
        read_log(tmp_path)  # a directory with one log under it (a demo run's) is that log
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "y.mcap").write_bytes(content)
    with pytest.raises(UserError, match="is a directory; the logs under it: .*x.mcap, .*y.mcap"):
        read_log(tmp_path)  # after --compare each planner's log is in a directory of its own: they are named
    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError, match=r"is a directory, with no .mcap file under it \(yet: runs/demo/latest names a "
                       "demo run from its start"):  # a review read `latest` while --compare was starting
        read_log(tmp_path / "empty")


def test_a_copy_cut_within_its_closing_magic_is_not_complete(tmp_path, pr2) -> None:
    path = tmp_path / "run.mcap"
    _log(path, pr2, rounds=2)
    path.write_bytes(path.read_bytes()[:-3])
    lf = read_log(path)
    assert not lf.complete and lf.error


def test_a_second_writer_on_the_path_is_refused_and_the_first_log_is_kept(tmp_path, pr2) -> None:
    """Two runs on one path (two executors started within the same second, or one given the other's --mcap): the
    second emptied the file and the first run's messages were gone, both saying they wrote their log."""
    path = tmp_path / "run.mcap"
    first = McapLog(path, KEYS, None)
    for key, payload in sample_messages(pr2):
        first.on_sample(key, payload)
    with pytest.raises(OSError, match="another run is writing this log"):
        McapLog(path, KEYS, None)
    first.close()
    lf = read_log(path)
    assert lf.complete and lf.message_count == len(sample_messages(pr2))
    McapLog(path, KEYS, None).close()  # once the first has closed, the path may be written again


def test_a_log_deleted_while_written_says_so_rather_than_that_it_wrote(tmp_path, pr2, caplog) -> None:
    run = tmp_path / "run"
    run.mkdir()
    log = McapLog(run / "run.mcap", KEYS, None, flush_period_s=0.0)
    for key, payload in sample_messages(pr2):
        log.on_sample(key, payload)
    for f in run.iterdir():
        f.unlink()
    run.rmdir()  # a clean-up of runs/ during the run
    with caplog.at_level("ERROR"):
        log.flush()
        log.flush()
        with pytest.raises(OSError, match="deleted while it was written"):
            log.close()
    said = [r.getMessage() for r in caplog.records]
    assert sum("deleted while it is written" in m for m in said) == 1
    assert any("deleted while it was written" in m and "messages are lost" in m for m in said)
    assert not any("readers recover" in m for m in said)  # there is no file left to read
    assert not any("wrote" in m for m in said)


def test_a_file_system_that_takes_no_lock_still_gets_its_log_and_no_descriptor_leaks(tmp_path, pr2, monkeypatch,
                                                                                    caplog) -> None:
    """NFS without its lock daemon answers flock with ENOLCK: the log was refused there, its descriptor left open."""
    def no_locks(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(direct_file.fcntl, "flock", no_locks)
    fds = len(os.listdir("/proc/self/fd"))
    with caplog.at_level("WARNING"):
        log = McapLog(tmp_path / "run.mcap", KEYS, None)
        for key, payload in sample_messages(pr2):
            log.on_sample(key, payload)
        log.close()
    assert read_log(tmp_path / "run.mcap").complete and any("takes no lock" in r.getMessage() for r in caplog.records)

    def refused(fd: int, op: int) -> None:
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    monkeypatch.setattr(direct_file.fcntl, "flock", refused)
    with pytest.raises(OSError, match="Input/output error"):
        McapLog(tmp_path / "other.mcap", KEYS, None)
    assert len(os.listdir("/proc/self/fd")) == fds


def test_a_time_mcap_cannot_hold_is_refused_before_the_record_is_begun(tmp_path, pr2) -> None:
    """A stamp of 1e11 s (1e20 ns, past uint64) failed half-way through its record: the file read as complete, with
    messages missing and a garbage one in their place (a review)."""
    from shared.protocol import ClockTick, encode

    path = tmp_path / "run.mcap"
    log = McapLog(path, KEYS, None)
    sent = sample_messages(pr2)
    for key, payload in sent[:3]:
        log.on_sample(key, payload)
    for stamp in (1e11, 1e300):
        with pytest.raises(ValueError, match=r"message on foresight/x/tick not written: its publish time .* is not an "
                                             r"MCAP time"):
            log.on_sample("foresight/x/tick", encode(ClockTick(stamp=stamp, tick=5, period=0.1)))
    with pytest.raises(ValueError, match="its log time -1 ns is not an MCAP time"):
        log.write_ros2("/clock", "rosgraph_msgs/msg/Clock", b"\x00\x01\x00\x00" + bytes(8), log_time=-1)
    with pytest.raises(ValueError, match=f"its log time {2 ** 64} ns"):
        log.write_rejected({"key": "k"}, log_time=2 ** 64)
    for key, payload in sent[3:]:
        log.on_sample(key, payload)
    log.close()
    lf = read_log(path, keep=lambda ch: True)
    assert lf.complete and [(m.topic, m.data) for m in lf.messages] == [(k, p) for k, p in sent]
    assert sum(c.count for c in lf.channels.values()) == len(sent)


def test_a_pipe_or_a_file_in_the_way_is_named_and_left_alone(tmp_path, monkeypatch) -> None:
    """A FIFO given as the log blocked the open (a device failed with "[Errno 22] Invalid argument", naming nothing);
    a file where a directory is needed said "text.mcap: File exists"."""
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # a reader: a writer's open of the pipe cannot hang the test
    try:
        with pytest.raises(OSError) as exc:
            McapLog(fifo, KEYS, None)
    finally:
        os.close(reader)
    assert exc.value.filename == str(fifo) and "a named pipe (FIFO) is there, not a regular file" in str(exc.value)
    (tmp_path / "text.mcap").write_text("notes")
    with pytest.raises(NotADirectoryError) as exc:
        McapLog(tmp_path / "text.mcap" / "sub.mcap", KEYS, None)
    assert exc.value.filename == str(tmp_path / "text.mcap") and "a file is in the way" in str(exc.value)

    def refused(fd: int, length: int) -> None:  # what a character device answers (not one of /dev here)
        raise OSError(errno.EINVAL, os.strerror(errno.EINVAL))

    monkeypatch.setattr(direct_file.os, "ftruncate", refused)
    fds = len(os.listdir("/proc/self/fd"))
    with pytest.raises(OSError) as exc:
        McapLog(tmp_path / "dev.mcap", KEYS, None)
    assert exc.value.filename == str(tmp_path / "dev.mcap") and "cannot empty the file" in str(exc.value)
    assert len(os.listdir("/proc/self/fd")) == fds
