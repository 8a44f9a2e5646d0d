"""The demo's run directories: ``latest`` points to the newest run whose services started (and wrote a log)."""

from __future__ import annotations

from services.demo_dirs import RunDirectory


def test_a_run_ended_before_its_log_hands_latest_back_and_keeps_its_service_logs(tmp_path) -> None:
    """After a Ctrl-C during start-up ``latest`` pointed to a run with no MCAP: ``foresight log info
    runs/demo/latest``, the README's next command, found nothing while the earlier runs' logs were there."""
    before = RunDirectory.create(tmp_path, "lockstep", False)
    before.point_latest()
    (before.path / "run.mcap").write_bytes(b"a log")
    run = RunDirectory.create(tmp_path, "lockstep", False)
    assert run.path != before.path and run.path.name.startswith(before.path.name[:16])
    run.point_latest()
    run.point_latest()  # --compare: each planner's services start; the run before is still the one to hand back to
    assert (tmp_path / "latest").resolve() == run.path.resolve()  # during the run: its services' logs
    (run.path / "planner.log").write_text("started\n")
    assert not run.has_log()
    run.end_without_log()
    assert (tmp_path / "latest").resolve() == before.path.resolve() and (run.path / "planner.log").exists()


def test_a_run_nothing_was_written_into_is_removed_and_a_first_run_leaves_no_link(tmp_path) -> None:
    run = RunDirectory.create(tmp_path, "realtime", True)
    assert run.path.name.endswith("-realtime-compare")
    run.point_latest()
    run.end_without_log()
    assert not run.path.exists() and not (tmp_path / "latest").is_symlink()  # nothing to hand back to: no link


def test_two_demos_started_in_the_same_second_get_a_directory_each(tmp_path, monkeypatch) -> None:
    """The name was checked, then made: two demos between the two steps both took it, and one failed ('File
    exists', status 2) in 5 of 5 of a review's trials. The race is played here by a check that always says free."""
    from pathlib import Path

    first = RunDirectory.create(tmp_path, "lockstep", False)
    monkeypatch.setattr(Path, "exists", lambda self: False)  # the other demo made it after this one looked
    second = RunDirectory.create(tmp_path, "lockstep", False)
    third = RunDirectory.create(tmp_path, "lockstep", False)
    assert len({first.path, second.path, third.path}) == 3 and all(p.path.is_dir() for p in (first, second, third))


def test_a_run_ended_before_its_first_plan_says_where_its_files_are_and_where_latest_points(tmp_path) -> None:
    """A new user's Ctrl-C as the services started: `latest` went back to the run before, and nothing named the
    directory the interrupted run's logs were in."""
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    before = RunDirectory.create(tmp_path, "lockstep", False)
    before.point_latest()
    with McapLog(before.path / "before.mcap", Keys()):
        pass
    run = RunDirectory.create(tmp_path, "lockstep", False)
    run.point_latest()
    (run.path / "planner.log").write_text("started\n")
    run.end_without_log()
    assert run.whereabouts() == (f"this run's files: {run.path}/: its services' logs, no MCAP log (the executor had "
                                 f"not opened one); {tmp_path / 'latest'} still points to {before.path.name}, the run "
                                 "before (a run without an MCAP log hands it back)")
    assert before.whereabouts() == (f"this run's files: {before.path}/: its services' logs and MCAP log before.mcap "
                                    f"(complete); {tmp_path / 'latest'} points to it")
    cut = before.path / "before.mcap"
    cut.write_bytes(cut.read_bytes()[:-30])  # no footer: the executor did not finalise it
    (before.path / "empty.mcap").write_bytes(b"")
    said = before.whereabouts()
    assert "before.mcap (TRUNCATED (" in said and "empty.mcap (unreadable: " in said, said
    run.end_without_log()
    (tmp_path / "latest").unlink()
    assert run.whereabouts().endswith(f"; no {tmp_path / 'latest'} link")


def test_a_run_nothing_was_kept_of_says_nothing(tmp_path) -> None:
    run = RunDirectory.create(tmp_path, "lockstep", False)
    run.end_without_log()
    assert run.whereabouts() is None


def test_the_demo_takes_the_executors_incomplete_log_line_and_checks_a_log_it_did_not_hear_about(tmp_path) -> None:
    from services.demo_dirs import describe_log, log_incomplete
    from services.executor.result import LOG_INCOMPLETE
    from shared.protocol import Keys
    from shared.recording.writer import McapLog

    class Executor:
        returncode = LOG_INCOMPLETE

        def tail(self, lines: int = 3) -> str:
            return ("executor: done after 20 steps\nmcap: run.mcap: INCOMPLETE: 9 of 20 messages written (No space "
                    "left on device: 12 bytes refused for 3 s)\nzenoh: closed")

    said = log_incomplete(Executor())  # the executor's own line, whatever its log says after it
    assert said == {"log_incomplete": "run.mcap: INCOMPLETE: 9 of 20 messages written (No space left on device: 12 "
                                      "bytes refused for 3 s)"}
    Executor.returncode = 0
    assert log_incomplete(Executor()) == {} and log_incomplete(None) == {}
    mcap = tmp_path / "run.mcap"
    with McapLog(mcap, Keys()):
        pass
    assert describe_log(str(mcap)) == str(mcap)
    assert describe_log(str(mcap), said=said["log_incomplete"]) == (
        f"{mcap} — INCOMPLETE: 9 of 20 messages written (No space left on device: 12 bytes refused for 3 s)")
    mcap.write_bytes(mcap.read_bytes()[:-8])  # its footer's magic gone: not complete, though no one said so
    assert describe_log(str(mcap)).startswith(f"{mcap} — INCOMPLETE: TRUNCATED (")
    assert describe_log(None) == "None" and describe_log(str(tmp_path / "none.mcap")) == str(tmp_path / "none.mcap")


def test_latest_is_said_to_point_where_it_does_after_a_first_run_without_an_mcap_log(tmp_path) -> None:
    """The demo's help said ``latest`` points to "the newest with an MCAP log"; after a Ctrl-C in the first run's
    planner start-up it points, on purpose, to that run, which has only its service logs (a review)."""
    import services.demo
    import services.demo_dirs

    run = RunDirectory.create(tmp_path, "lockstep", False)
    run.point_latest()
    (run.path / "planner.log").write_text("stopped while starting\n")
    run.end_without_log()
    assert (tmp_path / "latest").resolve() == run.path.resolve() and not run.has_log()
    for doc in (services.demo.__doc__, services.demo_dirs.__doc__):
        assert "newest with an MCAP log" not in " ".join(doc.split())
    assert "unless there is none: then it points to that run's service logs" in " ".join(services.demo.__doc__.split())
