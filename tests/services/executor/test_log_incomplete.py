"""A run whose MCAP log a full disk cut short says how many messages it lost, and ends with its own status."""

from __future__ import annotations

import re

import pytest

from services.executor.core import ExecutorConfig
from services.executor.service import ExecutorService
from shared.recording.reader import read_log

from .conftest import SCENE
from .test_service import run_on_a_disk_full_after


def test_a_full_disk_makes_the_run_say_how_many_messages_its_log_lost(pr2, tmp_path, monkeypatch, caplog) -> None:
    """The disk fills during the run: every write was held, the close failed with one error line, and the run
    returned as a whole one (status 0, `mcap: PATH`): half the log gone without a word in the result."""
    monkeypatch.setattr("shared.recording.writer.CLOSE_RETRY_S", 0.2)
    cfg, result = run_on_a_disk_full_after(8192, pr2, tmp_path, monkeypatch)
    assert result.steps == 10
    m = re.fullmatch(r".*run\.mcap: INCOMPLETE: (\d+) of (\d+) messages written \(No space left on device: .*\)",
                     result.log_incomplete)
    assert m is not None, result.log_incomplete
    written, total = int(m[1]), int(m[2])
    assert written == read_log(cfg.mcap).message_count and written < total
    assert result.log_lost == total - written


def test_an_incomplete_log_is_the_executors_exit_status_and_last_line(monkeypatch, capsys) -> None:
    import services.executor.__main__ as executor_main
    from services.executor.result import ExecutorResult

    class Ran:
        def __init__(self, *_a) -> None:
            pass

        def run(self) -> ExecutorResult:
            return ExecutorResult(mcap_path="runs/x.mcap", lockstep_timeouts=1, log_incomplete=self.said)

    argv = ["--mode", "lockstep", "--steps", "1", "--connect", "tcp/127.0.0.1:9"]
    monkeypatch.setattr(executor_main, "ExecutorService", Ran)
    Ran.said = "runs/x.mcap: INCOMPLETE: 5 of 9 messages written (No space left on device: 99 bytes refused for 3 s)"
    assert executor_main.main(argv) == executor_main.LOG_INCOMPLETE == 4
    assert capsys.readouterr().out.splitlines()[-1] == f"mcap: {Ran.said}"
    Ran.said = ""
    assert executor_main.main(argv) == executor_main.INCOMPLETE
    assert capsys.readouterr().out.splitlines()[-1] == "mcap: runs/x.mcap"


@pytest.mark.parametrize("late", [0, 2])
def test_messages_after_the_log_closed_are_in_the_result(pr2, tmp_path, late) -> None:
    from shared.config import ZenohConfig
    from shared.recording.writer import McapLog

    service = ExecutorService(ExecutorConfig(), ZenohConfig(listen=[], connect=[]), robot=pr2, human=(None, None),
                              scene=SCENE)
    service.mcap = McapLog(tmp_path / "run.mcap", service.keys, None, flush_period_s=0.0)
    service._close_log()
    for _ in range(late):
        service._record_ros2("/joint_states", "sensor_msgs/msg/JointState", b"")
    assert service.result.log_incomplete == "" and service.mcap.dropped_after_close == late


def test_a_full_disk_under_the_executors_output_leaves_its_status(monkeypatch) -> None:
    """A review filled the disk: the ``mcap:`` line raised ENOSPC and status 4 (its log incomplete) became 1."""
    import errno

    import services.executor.__main__ as executor_main
    from services.executor.result import ExecutorResult

    class Ran:
        def __init__(self, *_a) -> None:
            pass

        def run(self) -> ExecutorResult:
            return ExecutorResult(mcap_path="runs/x.mcap", log_incomplete="runs/x.mcap: INCOMPLETE: 0 of 9 messages")

    class Full:  # stdout on a full disk
        def write(self, text: str) -> int:
            raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self) -> None:
            raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(executor_main, "ExecutorService", Ran)
    monkeypatch.setattr("sys.stdout", Full())
    assert executor_main.main(["--mode", "lockstep", "--steps", "1", "--connect", "tcp/127.0.0.1:9"]) == 4
