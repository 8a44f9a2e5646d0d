"""A damaged chunk of a finished log is skipped, not the end of it; damage is called DAMAGED, never TRUNCATED."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import pytest

from shared.protocol import Keys
from shared.recording.reader import iter_messages, read_log
from shared.recording.writer import McapLog
from shared.runtime import UserError

from .conftest import sample_messages

KEYS = Keys()


def _write(log: McapLog, pr2, rounds: int) -> int:
    for _ in range(rounds):
        for key, payload in sample_messages(pr2):
            log.on_sample(key, payload)
    return rounds * len(sample_messages(pr2))


def _small_log(path: Path, pr2, rounds: int = 12) -> int:
    """A finished log of many small chunks; returns its message count."""
    log = McapLog(path, KEYS, None, chunk_size=2048, compression="none", scene_text="name = 'scene'\n" * 4,
                  run_metadata={"mode": "lockstep", "steps": "2"})
    sent = _write(log, pr2, rounds)
    log.close()
    return sent


def _chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, length) of each top-level chunk record, walking the records from the magic to the data's end."""
    at, out = 8, []
    while at + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode in (0x0F, 0x02):  # data end, footer
            break
        if opcode == 0x06:
            out.append((at, length))
        at += 9 + length
    return out


def _flip_in_chunk(path: Path, which: int) -> None:
    data = bytearray(path.read_bytes())
    at, length = _chunks(bytes(data))[which]
    data[at + 9 + length - 40] ^= 0xFF  # inside its records, past its own fields
    path.write_bytes(bytes(data))


def test_a_damaged_chunk_of_a_finished_log_is_skipped_and_the_rest_read(tmp_path, pr2) -> None:
    """One flipped byte in a chunk lost every chunk after it, and the log was called TRUNCATED (a review)."""
    path = tmp_path / "run.mcap"
    sent = _small_log(path, pr2)
    assert len(_chunks(path.read_bytes())) > 4
    last = read_log(path).channels
    _flip_in_chunk(path, 1)
    lf = read_log(path)
    assert not lf.complete and lf.chunks_skipped == 1 and lf.messages_lost
    assert re.match(rf"DAMAGED \(1 chunk failing its CRC skipped: {lf.messages_lost} messages? lost \(CRC", lf.state)
    assert "TRUNCATED" not in lf.state
    assert lf.message_count + lf.messages_lost == sent  # every other chunk read, the last one's messages too
    assert {c.topic: c.last_time for c in lf.channels.values()} == {c.topic: c.last_time for c in last.values()}
    assert len(list(iter_messages(path))) == lf.message_count  # the message readers agree


def test_a_damaged_metadata_record_or_attachment_is_damage_not_truncation(tmp_path, pr2) -> None:
    """A failed data-section CRC said TRUNCATED of a whole file; an attachment's own CRC was not checked."""
    path = tmp_path / "run.mcap"
    sent = _small_log(path, pr2, rounds=2)
    good = path.read_bytes()
    data = bytearray(good)
    data[data.index(b"lockstep")] ^= 0x20  # the run's metadata: mode=Lockstep
    path.write_bytes(bytes(data))
    lf = read_log(path)
    assert lf.state.startswith("DAMAGED (metadata/attachments: the data section fails its CRC") and lf.error
    assert lf.message_count == sent and "TRUNCATED" not in lf.state
    data = bytearray(good)
    data[data.index(b"name = 'scene'") + 3] ^= 0x20
    path.write_bytes(bytes(data))
    lf = read_log(path)
    assert lf.state.startswith("DAMAGED (metadata/attachments: the attachment 'scene.toml' fails its CRC")
    assert "scene.toml" not in lf.attachments and lf.message_count == sent  # not drawn as the run's scene


def test_a_damaged_chunk_of_a_log_still_being_written_is_damage(tmp_path, pr2) -> None:
    """A live log with a damaged chunk said only STILL BEING WRITTEN (a review)."""
    path = tmp_path / "run.mcap"
    log = McapLog(path, KEYS, None, chunk_size=2048, compression="none")
    try:
        _write(log, pr2, 8)
        log.flush()
        assert read_log(path).state.startswith("STILL BEING WRITTEN")
        _flip_in_chunk(path, 1)
        lf = read_log(path)
        assert lf.being_written and lf.state.startswith("DAMAGED (a chunk failing its CRC (CRCValidationError")
        assert lf.state.endswith("; a run holds its lock)")
    finally:
        log.close()


@pytest.mark.parametrize("cut", [9, 20, 40])
def test_a_file_cut_inside_its_header_says_so(tmp_path, pr2, cut: int) -> None:
    """It read as TRUNCATED with 0 messages recovered (status 0); compress said "not an MCAP file (EndOfFile: )"."""
    path = tmp_path / "run.mcap"
    _small_log(path, pr2, rounds=1)
    path.write_bytes(path.read_bytes()[:cut])
    with pytest.raises(UserError, match=r"run\.mcap: not an MCAP file: truncated before its header ends \("):
        read_log(path)
