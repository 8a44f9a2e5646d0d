"""What the `foresight log` commands say of a damaged or truncated log, and where they write (a review's findings)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from shared.recording.reader import read_log
from tools.log.cli import main
from tools.log.compress import compress_log


def _flipped(run_log: Path, tmp_path: Path) -> Path:
    """A copy of ``run_log`` in small uncompressed chunks, its second chunk with one byte flipped."""
    packed, bad = tmp_path / "packed.mcap", tmp_path / "bad.mcap"
    compress_log(run_log, packed, "none", chunk_size=4096)
    data, at, chunks = bytearray(packed.read_bytes()), 8, []
    while at + 9 <= len(data):  # the top-level records, up to the data section's end
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode in (0x0F, 0x02):
            break
        chunks += [(at, length)] if opcode == 0x06 else []
        at += 9 + length
    at, length = chunks[1]
    data[at + 9 + length - 40] ^= 0xFF
    bad.write_bytes(bytes(data))
    return bad


def _fails(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1, err
    return err[0]


def test_compress_of_a_damaged_log_fails_and_its_copy_says_damaged(run_log: Path, tmp_path: Path, capsys) -> None:
    """It said "read back identical" and exited 0, copying the messages before the damage only (a review)."""
    bad = _flipped(run_log, tmp_path)
    lf = read_log(bad)
    assert lf.chunks_skipped == 1 and lf.message_count + lf.messages_lost == read_log(run_log).message_count
    assert main(["compress", str(bad), str(tmp_path / "copy.mcap")]) == 1
    out = capsys.readouterr().out
    assert "the input is DAMAGED (1 chunk failing its CRC skipped" in out and "TRUNCATED" not in out
    assert read_log(tmp_path / "copy.mcap").message_count == lf.message_count
    assert main(["info", str(tmp_path / "copy.mcap")]) == 0
    out = capsys.readouterr().out
    assert "complete; copied from a DAMAGED log (1 chunk failing its CRC skipped" in out and "TRUNCATED" not in out


def test_a_copy_of_a_log_with_damaged_metadata_does_not_say_truncated(run_log: Path, tmp_path: Path, capsys) -> None:
    data = bytearray(run_log.read_bytes())
    data[data.index(b"lockstep")] ^= 0x20
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["info", str(bad)]) == 0
    assert "DAMAGED (metadata/attachments: the data section fails its CRC" in capsys.readouterr().out
    assert main(["compress", str(bad), str(tmp_path / "copy.mcap")]) == 1
    capsys.readouterr()
    assert main(["info", str(tmp_path / "copy.mcap")]) == 0
    out = capsys.readouterr().out
    assert "copied from a DAMAGED log (metadata/attachments" in out and "TRUNCATED" not in out


@pytest.mark.parametrize("command", [["table"], ["latency"], ["render", "--step", "0", "--out", "{tmp}/r.png"]])
def test_a_log_without_plans_says_its_state_when_it_is_not_complete(run_log: Path, tmp_path: Path, capsys,
                                                                    command: list[str]) -> None:
    """"no plans logged" of a truncated log, without a word of why (a review)."""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_log.read_bytes()[:400])  # the header and the first schemas: no message whole
    err = _fails([command[0], str(cut), *(a.format(tmp=tmp_path) for a in command[1:])], capsys)
    assert "(the log is TRUNCATED (" in err, err


def test_render_says_plans_of_a_real_time_run_and_writes_plan_pngs(tmp_path: Path, robot, capsys) -> None:
    """"no plan for step 99 (steps 0..65)" of a real-time run whose plans are numbered, not steps (a review)."""
    from shared.protocol import Keys, Plan, RobotState, encode
    from shared.recording.writer import McapLog

    keys, t0, q0 = Keys(), 1_700_000_000.0, robot.q_start.numpy().astype(np.float64)
    now = [t0]
    path = tmp_path / "rt.mcap"
    log = McapLog(path, keys, None, clock=lambda: int(now[0] * 1e9))
    traj = np.stack([np.linspace(q0, q0 + 0.1, 5)] * 2).astype(np.float32)
    for n, (made, arrives) in enumerate([(0.0, 0.01), (0.02, 0.03), (0.02, 0.035)]):
        now[0] = t0 + made
        log.on_sample(keys.robot_state, encode(RobotState(stamp=t0 + made, tick=-1, joint_names=robot.joint_names,
                                                          goal=0, reached=False, holding=False, reason="", q=q0,
                                                          qd=np.zeros(8))))
        now[0] = t0 + arrives
        log.on_sample(keys.plan, encode(Plan(stamp=t0 + made, tick=-1, step=n, goal_names=["blue_cup", "red_cup"],
                                             joint_names=robot.joint_names, dt=0.1, chosen=0, planning_ms=10.0,
                                             occupancy_tick=-1, occupancy_index=0, trajectories=traj,
                                             cost_smoothness=np.ones(2), cost_obstacle=np.zeros(2),
                                             cost_human=np.zeros(2), cost_total=np.ones(2), valid=np.ones(2, bool))))
    now[0] = t0 + 0.04
    log.on_sample(keys.robot_state, encode(RobotState(stamp=t0 + 0.04, tick=-1, joint_names=robot.joint_names, goal=0,
                                                      reached=False, holding=False, reason="", q=q0, qd=np.zeros(8))))
    log.close()
    err = _fails(["render", str(path), "--step", "99", "--out", str(tmp_path / "x.png")], capsys)
    assert err.endswith(f"{path}: no plan 99 (plans 0, 2)"), err
    assert main(["render", str(path), "--all", "--out", str(tmp_path / "all")]) == 0
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["plan_000.png", "plan_002.png"]
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    assert "a real-time run's: plan N" in " ".join(capsys.readouterr().out.split())  # --help said Plan.step only


def test_compress_refuses_to_replace_a_file_that_is_not_a_log_and_says_when_it_makes_a_directory(
        run_log: Path, tmp_path: Path, capsys) -> None:
    """`compress SRC keep.txt` replaced keep.txt without a word (a review)."""
    keep = tmp_path / "keep.txt"
    keep.write_text("notes\n")
    err = _fails(["compress", str(run_log), str(keep)], capsys)
    assert err.endswith(f"{keep} exists and is not an MCAP file: not replaced (remove it, or give another output)")
    assert keep.read_text() == "notes\n"
    assert main(["compress", str(run_log), str(tmp_path / "new" / "c.mcap")]) == 0
    assert f"foresight log: note: made the directory {tmp_path / 'new'}" in capsys.readouterr().err
    assert main(["compress", str(run_log), str(tmp_path / "new" / "c.mcap")]) == 0  # a log: replaced, as before
    assert "made the directory" not in capsys.readouterr().err


@pytest.mark.parametrize("command", [["render", "{log}", "--step", "0", "--out", "{tmp}/nd/r.png"],
                                     ["render", "{log}", "--all", "--out", "{tmp}/nd/all"],
                                     ["snapshot", "{log}", "--out", "{tmp}/nd/s.png"]])
def test_a_failed_command_leaves_no_directory_behind(tmp_path: Path, capsys, command: list[str]) -> None:
    """render and snapshot made --out's directories before reading the log, and left them on failure (a review)."""
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not a log at all")
    _fails([a.format(log=bad, tmp=tmp_path) for a in command], capsys)
    assert not (tmp_path / "nd").exists()


def test_a_file_cut_inside_its_header_is_said_so_by_info_and_compress(run_log: Path, tmp_path: Path, capsys) -> None:
    """info said "TRUNCATED ... recovered 0 messages" (status 0), compress "not an MCAP file (EndOfFile: )"."""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(run_log.read_bytes()[:20])
    for argv in (["info", str(cut)], ["compress", str(cut), str(tmp_path / "c.mcap")]):
        err = _fails(argv, capsys)
        assert f"{cut}: not an MCAP file: truncated before its header ends (" in err, err
