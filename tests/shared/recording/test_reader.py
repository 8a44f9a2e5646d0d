"""read_log: record by record, keeping the payloads asked for, tolerating a truncated end."""

from __future__ import annotations

import numpy as np
import pytest

from shared.protocol import ClockTick, Keys, decode, encode
from shared.recording.reader import read_log
from shared.recording.writer import McapLog
from shared.runtime import UserError

KEYS = Keys()


def write_clock_log(path, n: int) -> None:
    with McapLog(path, KEYS, None, chunk_size=1024, scene_text="name = 'x'", run_metadata={"mode": "lockstep"}) as log:
        for k in range(n):
            log.on_sample(KEYS.clock, encode(ClockTick(stamp=0.2 * k, tick=k, period=0.2)))
        log.on_sample(KEYS.clock, b"\xc1")


def test_reads_channels_payloads_attachments_and_metadata(tmp_path) -> None:
    path = tmp_path / "a.mcap"
    write_clock_log(path, 50)
    lf = read_log(path, keep=lambda ch: ch.topic == KEYS.clock)
    assert lf.complete and not lf.error and lf.profile == "foresight"
    counts = {c.topic: c.count for c in lf.channels.values()}
    assert counts == {KEYS.clock: 50, "/foresight/rejected": 1}
    assert [decode(m.data, ClockTick).tick for m in lf.topic_messages(KEYS.clock)] == list(range(50))
    assert lf.attachments == {"scene.toml": b"name = 'x'"}
    assert lf.metadata["foresight.run"] == {"mode": "lockstep"}
    assert lf.metadata["foresight.rejects"] == {KEYS.clock: "1"}
    assert read_log(path).messages == []  # counts only unless asked
    assert lf.message_count == 51


def test_a_truncated_file_is_read_up_to_its_last_whole_chunk(tmp_path) -> None:
    path = tmp_path / "a.mcap"
    write_clock_log(path, 400)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    lf = read_log(cut, keep=lambda ch: True)
    assert not lf.complete and lf.error
    ticks = [decode(m.data, ClockTick).tick for m in lf.topic_messages(KEYS.clock)]
    assert 0 < len(ticks) < 400 and ticks == list(range(len(ticks)))
    assert np.all(np.diff([m.log_time for m in lf.topic_messages(KEYS.clock)]) >= 0)


@pytest.mark.parametrize("content, message", [(None, "not found"), (b"hello, this is not mcap", "not an MCAP file")])
def test_missing_or_foreign_files_are_user_errors(tmp_path, content, message) -> None:
    path = tmp_path / "x.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(UserError, match=message):
        read_log(path)
