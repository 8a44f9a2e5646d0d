"""Every `foresight log` command on a damaged log: one line or a partial result, never a traceback."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from shared.recording.reader import read_log
from tools.log.cli import main
from tools.log.compress import compress_log

FRAME_MAGIC = {"zstd": b"\x28\xb5\x2f\xfd", "lz4": b"\x04\x22\x4d\x18"}


def _chunks_flipped(src: Path, dst: Path, compression: str, tmp_path: Path) -> None:
    """A copy of ``src`` with ``compression`` chunks, one of them damaged.

    Compressed: the frame descriptor after the second chunk's frame magic is garbled, so that the chunk does not
    decompress (zstandard and lz4 raise their own errors); uncompressed: one byte in the middle of the file flipped.
    """
    packed = tmp_path / f"packed-{compression}.mcap"
    compress_log(src, packed, compression, chunk_size=4096)
    data = bytearray(packed.read_bytes())
    if compression in FRAME_MAGIC:
        at = data.find(FRAME_MAGIC[compression], data.find(FRAME_MAGIC[compression]) + 1)
        assert at > 0
        data[at + 4: at + 8] = b"\xff\xff\xff\xff"
    else:
        data[len(data) // 2] ^= 0xFF
    dst.write_bytes(bytes(data))


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize("command", ["info", "latency", "table", "render", "snapshot", "compress"])
def test_a_damaged_chunk_is_reported_not_raised(run_log: Path, tmp_path: Path, capsys, compression: str,
                                                command: str) -> None:
    bad = tmp_path / "bad.mcap"
    _chunks_flipped(run_log, bad, compression, tmp_path)
    args = {"info": [str(bad)], "latency": [str(bad)], "table": [str(bad)],
            "render": [str(bad), "--out", str(tmp_path / "r.png")],
            "snapshot": [str(bad), "--out", str(tmp_path / "s.png")],
            "compress": [str(bad), str(tmp_path / "c.mcap")]}[command]
    try:
        rc = main([command, *args])
    except SystemExit as stop:  # a one-line error, status 2
        rc = stop.code
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and err[0].startswith(f"foresight log {command}: error:"), err
    assert rc in ((1,) if command == "compress" else (0, 2))  # compress: its copy lacks the damaged chunk's messages


def test_a_flipped_byte_is_found_by_the_chunk_crc(run_log: Path, tmp_path: Path, capsys) -> None:
    """Uncompressed chunks carry a CRC: a changed payload is reported, not read as complete and identical."""
    bad = tmp_path / "bad.mcap"
    _chunks_flipped(run_log, bad, "none", tmp_path)
    log = read_log(bad)
    assert not log.complete and "crc" in log.error.lower()
    assert log.message_count < read_log(run_log).message_count


def test_compress_of_a_log_cut_anywhere_leaves_a_readable_copy_or_nothing(run_log: Path, tmp_path: Path) -> None:
    data = run_log.read_bytes()
    for cut in range(8, len(data), max(1, len(data) // 97)):
        src, dst = tmp_path / "cut.mcap", tmp_path / "out.mcap"
        src.write_bytes(data[:cut])
        try:
            main(["compress", str(src), str(dst)])
        except SystemExit as stop:
            assert stop.code == 2, cut
            assert not dst.exists(), cut  # nothing half-written left behind
            continue
        assert read_log(dst).complete, cut


def test_a_path_that_cannot_be_written_is_one_line(run_log: Path, tmp_path: Path, capsys) -> None:
    (tmp_path / "afile").write_text("")
    for out in (tmp_path, tmp_path / "afile" / "x.mcap"):
        with pytest.raises(SystemExit) as stop:
            main(["compress", str(run_log), str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert stop.value.code == 2 and len(err) == 1 and str(out.parent if out.name == "x.mcap" else out) in err[0]


@pytest.mark.parametrize("text", [b"not [[ toml", b"\xff\xfe scene"])
def test_an_unreadable_scene_attachment_is_named(text: bytes) -> None:
    from shared.recording.reader import LogFile
    from shared.runtime import UserError
    from tools.log.steps import scene_of

    with pytest.raises(UserError, match=r"^run\.mcap: its scene\.toml attachment is unreadable"):
        scene_of(LogFile("run.mcap", 0, attachments={"scene.toml": text}))


def test_compress_leaves_an_existing_output_alone_when_the_input_is_bad_and_refuses_a_hard_link(
        run_log: Path, tmp_path: Path, capsys) -> None:
    """OUT was emptied before IN was read: a typo in IN deleted yesterday's log; a hard link emptied IN."""
    kept = tmp_path / "yesterday.mcap"
    kept.write_bytes(run_log.read_bytes())
    (tmp_path / "typo.txt").write_text("not a log")
    for bad in (tmp_path / "typo.txt", tmp_path / "missing.mcap"):
        with pytest.raises(SystemExit):
            main(["compress", str(bad), str(kept)])
        assert kept.read_bytes() == run_log.read_bytes()
    link = tmp_path / "link.mcap"
    os.link(kept, link)
    with pytest.raises(SystemExit):
        main(["compress", str(kept), str(link)])
    assert "another file than the input" in capsys.readouterr().err
    assert kept.read_bytes() == run_log.read_bytes() and not list(tmp_path.glob(".*.tmp"))


def test_a_copy_of_a_truncated_log_says_so_and_the_tools_note_a_truncated_log(run_log: Path, tmp_path: Path,
                                                                              capsys) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_log.read_bytes()[: run_log.stat().st_size * 2 // 3])
    res = compress_log(cut, tmp_path / "copy.mcap")
    assert not res.input_complete and res.identical
    capsys.readouterr()
    assert main(["info", str(tmp_path / "copy.mcap")]) == 0
    assert "complete; copied from a TRUNCATED log" in capsys.readouterr().out
    assert main(["table", str(cut)]) == 0  # it printed a killed run's table as if the run had ended there
    assert "is TRUNCATED (" in capsys.readouterr().err


def test_a_snapshot_of_a_log_damaged_at_its_end_draws_the_scene_up_to_the_damage(run_log: Path, tmp_path: Path,
                                                                                   capsys) -> None:
    """info and table read such a log up to the damage; snapshot, which reads the scene through the index, refused
    the whole file ('not a readable MCAP file, or truncated') for one flipped byte in its last chunk."""
    from mcap.reader import make_reader

    packed = tmp_path / "packed.mcap"
    compress_log(run_log, packed, "none", chunk_size=4096)
    with packed.open("rb") as f:
        last = max(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(packed.read_bytes())
    data[last.chunk_start_offset + last.chunk_length - 50] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["snapshot", str(bad), "--out", str(tmp_path / "s.png")]) == 0
    err = capsys.readouterr().err
    assert "is DAMAGED (1 chunk failing its CRC skipped" in err and (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG"


def test_a_scene_payload_that_does_not_decode_is_raised_not_taken_for_a_damaged_chunk(tmp_path: Path) -> None:
    """SceneDecodeError is a ValueError, and ValueError means a damaged chunk to the reader: a complete log's bad
    payload ended its scene early, without a word (a review of the damaged-chunk change)."""
    import json

    from mcap.writer import Writer

    from shared.foxglove.decode import SceneDecodeError, read_scene

    path = tmp_path / "bad.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        cid = w.register_channel("/viz/chart", "json", w.register_schema("chart", "jsonschema", b"{}"))
        for t, data in ((1, json.dumps({"timestamp": {"sec": 0, "nsec": 1}}).encode()), (2, b"{not json")):
            w.add_message(cid, log_time=t, publish_time=t, data=data)
        w.finish()
    with pytest.raises(SceneDecodeError, match="/viz/chart"):
        list(read_scene(path))
