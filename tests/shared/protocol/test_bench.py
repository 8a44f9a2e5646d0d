"""``foresight bench codec``: every message timed against bare msgpack, each round trip checked."""

from __future__ import annotations

import json

import pytest

from services.bench import main as bench_main
from shared.protocol import MESSAGE_TYPES, decode, encode
from shared.protocol.bench import bench_messages


def test_the_bench_times_each_message_against_msgpack(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_main(["codec", "--loops", "2", "--repeats", "1", "--voxels", "50", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["message"] for r in rows] == [name for name, _ in bench_messages(voxels=50)]
    for r in rows:
        assert r["bytes"] > 0 and all(r[k] > 0 for k in ("encode", "pack", "decode", "unpack"))
        assert r["encode_ratio"] == pytest.approx(r["encode"] / r["pack"])


def test_the_messages_are_valid_wire_messages_of_the_kinds_a_run_sends() -> None:
    msgs = bench_messages(voxels=50)
    for _, m in msgs:
        assert encode(decode(encode(m), type(m))) == encode(m)
    assert {type(m).__name__ for _, m in msgs} <= set(MESSAGE_TYPES)


def test_a_bad_count_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        bench_main(["codec", "--loops", "0"])
    assert exc.value.code == 2 and "--loops must be >= 1, got 0" in capsys.readouterr().err
