"""A close says how many messages a full disk cost, retries first, and nothing given to a log goes without a trace."""

from __future__ import annotations

import errno
import itertools
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import shared.recording.direct_file as direct_file
from shared.protocol import Keys, RobotState, encode
from shared.recording.reader import read_log
from shared.recording.writer import McapLog

KEYS = Keys()
NAMES = [f"j{i}" for i in range(7)]


def state(i: int) -> bytes:
    return encode(RobotState(stamp=i * 0.02, tick=i // 25, joint_names=NAMES, goal=0, reached=False, holding=False,
                             reason="", q=np.full(7, i * 1e-3), qd=np.zeros(7)))


def _disk(monkeypatch, room: int) -> dict[str, int]:
    """os.write of the log's file takes at most ``room`` bytes in all, then refuses as a full disk does
    (``disk["room"]`` raised later: space comes back). Other files are written as usual."""
    real, disk = os.write, {"room": room, "fd": -1}

    def write(fd: int, data) -> int:
        if fd != disk["fd"]:
            return real(fd, data)
        if disk["room"] <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        n = real(fd, memoryview(data)[: disk["room"]])
        disk["room"] -= n
        return n

    monkeypatch.setattr(direct_file.os, "write", write)
    return disk


def _open(path: Path, disk: dict[str, int]) -> McapLog:
    log = McapLog(path, KEYS, None, flush_period_s=0.0, compression="none")
    disk["fd"] = log._file._fd  # the log's own file only: pytest's output is written as usual
    return log


def test_a_full_disk_at_the_close_says_how_many_messages_were_lost(tmp_path, monkeypatch, caplog) -> None:
    path = tmp_path / "run.mcap"
    disk = _disk(monkeypatch, room=1 << 30)
    log = _open(path, disk)
    disk["room"] = 60_000  # the disk fills during the run: every on_sample still succeeds (the bytes are held)
    monkeypatch.setattr("shared.recording.writer.CLOSE_RETRY_S", 0.2)
    for i in range(400):
        log.on_sample(KEYS.robot_state, state(i))
    with caplog.at_level("ERROR"), pytest.raises(OSError, match=r"INCOMPLETE: \d+ of 400 messages written") as exc:
        log.close()
    readable = read_log(path).message_count
    assert 0 < readable < 400
    assert exc.value.errno == errno.ENOSPC
    assert f"INCOMPLETE: {readable} of 400 messages written (No space left on device" in str(exc.value)
    assert log.ledger.lost == 400 - readable
    said = [r.getMessage() for r in caplog.records if "INCOMPLETE" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith(f"mcap log {path}: INCOMPLETE: {readable} of 400")


def test_space_back_within_the_close_retry_loses_nothing(tmp_path, monkeypatch) -> None:
    path = tmp_path / "run.mcap"
    disk = _disk(monkeypatch, room=1 << 30)
    log = _open(path, disk)
    disk["room"] = 10_000
    for i in range(300):
        log.on_sample(KEYS.robot_state, state(i))
    assert log._file.held > 0
    threading.Timer(0.3, lambda: disk.update(room=1 << 30)).start()  # space back after the close began
    t0 = time.monotonic()
    log.close()  # before, it gave up at once: ENOSPC, and the held bytes were thrown away
    assert time.monotonic() - t0 < 3.0
    lf = read_log(path)
    assert lf.complete and lf.message_count == 300 and log.ledger.lost == 0


def test_a_file_that_ended_still_writes_what_it_holds_at_the_close(tmp_path, monkeypatch) -> None:
    path = tmp_path / "run.mcap"
    disk = _disk(monkeypatch, room=1 << 30)
    monkeypatch.setattr(direct_file, "MAX_HELD_BYTES", 20_000)
    log = _open(path, disk)
    disk["room"] = 0
    refused = 0
    for i in range(300):
        try:
            log.on_sample(KEYS.robot_state, state(i))
        except OSError:
            refused += 1
    assert refused and log.ledger.refused == refused - 1  # the first: its chunk was taken (held) as the file ended
    threading.Timer(0.3, lambda: disk.update(room=1 << 30)).start()
    with pytest.raises(OSError, match=f"INCOMPLETE: {301 - refused} of 300 messages written"):
        log.close()
    assert read_log(path).message_count == 301 - refused  # the held chunks reached the disk once it took bytes


def test_messages_after_the_close_are_counted_and_said_once(tmp_path, caplog) -> None:
    log = McapLog(tmp_path / "run.mcap", KEYS, None, flush_period_s=0.0)
    log.on_sample(KEYS.robot_state, state(0))
    log.close()
    with caplog.at_level("WARNING"):
        log.on_sample(KEYS.robot_state, state(1))
        log.write_rejected({"key": "x"})
        log.write_ros2("/joint_states", "sensor_msgs/msg/JointState", b"")
    assert log.dropped_after_close == 3
    assert sum("after the log was closed" in r.getMessage() for r in caplog.records) == 1


def test_log_times_follow_file_order_with_writers_on_several_threads(tmp_path) -> None:
    ticks = itertools.count(1)

    def clock() -> int:
        t = next(ticks)
        time.sleep(0.0002)  # another thread runs between the reading and the write (it did before the lock)
        return t

    path = tmp_path / "run.mcap"
    log = McapLog(path, KEYS, None, flush_period_s=0.0, clock=clock)

    def write(t: int) -> None:
        for i in range(150):
            log.on_sample(KEYS.robot_state, state(t * 150 + i))

    threads = [threading.Thread(target=write, args=(t,)) for t in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    log.close()
    times = [m.log_time for m in read_log(path, keep=lambda c: True).messages]
    assert len(times) == 600 and times == sorted(times)


def test_the_ledger_keeps_only_the_chunks_not_yet_on_the_disk(tmp_path: Path) -> None:
    """A mark per chunk, dropped only at the close: a day's run at a flush a second kept 86 000 of them."""
    log = McapLog(tmp_path / "run.mcap", KEYS, None, flush_period_s=0.0, compression="none")
    for i in range(300):  # a chunk each: flushed after every message
        log.on_sample(KEYS.robot_state, state(i))
    assert len(log.ledger._marks) <= 1 and log.ledger.written == 300  # the count read after: it prunes too
    log.close()
    assert read_log(tmp_path / "run.mcap").message_count == 300
