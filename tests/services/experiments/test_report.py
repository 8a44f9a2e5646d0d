"""``foresight eval all --quick``: every experiment into one Markdown report with its PNGs (runs in CI)."""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

import pytest

from services.experiments.cli import main
from services.experiments.report import report_workers, run_parts
from services.experiments.sections import part_names
from shared.library import load_library, report_drops
from shared.runtime import UserError
from tests.shared.library.test_report import broken_library


@pytest.mark.slow
def test_quick_report_runs_and_writes_its_report_and_pngs(tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["all", "--quick", "--out", str(out), "--models-dir", str(tmp_path / "models")]) == 0
    text = (out / "report.md").read_text()
    # the terminal ends with the verdicts, not only with where the report is
    printed = capsys.readouterr().out
    assert "eval all: the paper's results, reproduced or not" in printed
    section = text.split("## The paper's results", 1)[1].split("\n## ", 1)[0]
    verdicts = [ln for ln in section.splitlines() if ln.startswith("- ")]
    assert verdicts and all(f"  {ln[2:].replace('**', '')}" in printed for ln in verdicts)
    headings = ("### Recognition (Fig. 6)", "### Interference (Table I)", "### Goal switch (Fig. 8-9)", "## Timing")
    for heading in headings:
        assert heading in text
    for png in ("recognition-synthetic.png", "interference-synthetic.png", "switch-synthetic.png"):
        assert (out / png).stat().st_size > 10_000, png
        assert f"]({png})" in text
    data = json.loads((out / "report.json").read_text(), parse_constant=_refuse)  # strict JSON: no NaN
    lib = data["libraries"]["synthetic"]
    assert set(lib) >= {"recognition", "interference", "switch", "prediction_ms"}
    assert len(lib["interference"]["basic"]) == 1
    assert f"Command: `foresight eval all --out {out} --quick --models-dir {tmp_path / 'models'}`" in text
    assert "paper:" in text  # every section compares with the paper's numbers
    assert "The paper's library is not in this report: " in text  # a --quick run said nothing of leaving it out
    # each part's run time, in the data and in the timing block
    assert set(lib["part_seconds"]) == set(part_names(tuple(data["protocols"])))
    assert all(v > 0 for v in lib["part_seconds"].values()) and "Each part's run time" in text


def test_the_report_says_why_the_papers_library_is_left_out(monkeypatch, tmp_path):
    import argparse

    from services.experiments import report

    args = argparse.Namespace(library="", libraries="")
    monkeypatch.setattr(report, "PAPER_LIBRARY", tmp_path)  # here
    assert "a --quick run leaves it out" in report._left_out(args, ["synthetic"])[0]
    assert report._left_out(args, ["synthetic", str(tmp_path)]) == []  # in the report
    assert report._left_out(argparse.Namespace(library="", libraries="synthetic"), ["synthetic"]) == []  # chosen
    monkeypatch.setattr(report, "PAPER_LIBRARY", tmp_path / "none")
    assert "it is not at" in report._left_out(args, ["synthetic"])[0]


def _refuse(word: str) -> None:
    raise AssertionError(f"report.json holds {word}, which strict JSON parsers refuse")


def test_the_reports_command_line_has_every_option_given() -> None:
    """It left out --libraries, --library, --models-dir and --workers: the report could not be run again from it."""
    import argparse

    from services.experiments.report import _command, add_report_arguments

    parser = argparse.ArgumentParser()
    add_report_arguments(parser)
    args = parser.parse_args(["--libraries", "synthetic,/data/lib", "--models-dir", "/m d", "--workers", "3",
                              "--library", "/p", "--protocols", "paper"])
    assert _command(args, Path("r")) == ("foresight eval all --out r --libraries synthetic,/data/lib --library /p "
                                         "--models-dir '/m d' --protocols paper --workers 3")
    assert _command(parser.parse_args(["--quick"]), Path("r")) == "foresight eval all --out r --quick"


def test_report_workers_default_to_one_per_core_plus_one(monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert report_workers() == 3
    assert report_workers(1) == 1 and report_workers(5) == 5
    monkeypatch.setattr(os, "cpu_count", lambda: None)  # unknown: one core
    assert report_workers() == 2
    with pytest.raises(UserError, match="--workers must be >= 0"):
        report_workers(-1)


def _fail_or_run_long(i: int, directory: str) -> int:
    """Job 0 fails once the others run; every other job runs for a minute, then leaves a mark."""
    if i == 0:
        time.sleep(0.5)
        raise ValueError("part 0 failed")
    Path(directory, f"{i}.started").touch()
    end = time.monotonic() + 60
    while time.monotonic() < end:
        time.sleep(0.05)
    Path(directory, f"{i}.finished").touch()
    return i


def test_a_failed_part_ends_the_report_at_once_and_the_parts_still_running(tmp_path):
    with pytest.raises(ValueError, match="part 0 failed"):
        run_parts(_fail_or_run_long, [(i, str(tmp_path)) for i in range(5)], workers=3, context="fork")
    assert list(tmp_path.glob("*.started"))  # others were running beside it...
    assert not list(tmp_path.glob("*.finished"))  # ...and were ended with it, not waited for
    assert run_parts(divmod, [(7, 2), (9, 4), (1, 1)], workers=2, context="fork") == [(3, 1), (2, 1), (1, 0)]


@pytest.mark.parametrize("libraries", ["synthetic,synthetic", "a/lib,b/lib", "synthetic,data/synthetic"])
def test_two_libraries_with_one_name_are_refused_before_anything_runs(tmp_path, capsys, libraries):
    out = tmp_path / "report"  # both would write the same PNGs and the same report.json key: the first lost
    with pytest.raises(SystemExit) as stop:
        main(["all", "--quick", "--libraries", libraries, "--out", str(out)])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is given twice" in err[0] and "different folder name" in err[0]
    assert not out.exists()


def _read_and_listen(path: str) -> list[str]:
    """Read a library in a worker; returns the drop lines that reached the library logger's handlers."""
    heard: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: heard.append(record.getMessage())  # type: ignore[method-assign]
    logging.getLogger("foresight.library").addHandler(handler)
    try:
        load_library(path)
    finally:
        logging.getLogger("foresight.library").removeHandler(handler)
    return heard


def test_the_workers_do_not_repeat_the_drops_the_report_said(tmp_path):
    lib = str(broken_library(tmp_path / "lib"))
    said = report_drops(load_library(lib, report=False))
    assert len(said) == 1
    jobs = [(lib,)] * 4
    heard = run_parts(_read_and_listen, jobs, workers=2, context="fork")
    assert all(h in ([], said) for h in heard) and 1 <= heard.count(said) <= 2  # once in each worker at most
    assert run_parts(_read_and_listen, jobs, workers=2, context="fork", said=said) == [[]] * 4


def test_bad_workers_leave_no_report_directory_and_one_worker_is_one_process(tmp_path, capsys, monkeypatch):
    """``--workers -1`` was refused after ``--out`` was made, leaving it empty; ``--workers 1`` ran the recognition's
    leave-one-out in 2 processes (library_section's default) all the same."""
    import argparse

    from services.experiments import sections
    from services.experiments.report import add_report_arguments, run_report

    out = tmp_path / "report"
    with pytest.raises(SystemExit) as stop:
        main(["all", "--workers", "-1", "--out", str(out), "--libraries", "synthetic"])
    assert stop.value.code == 2 and "--workers must be >= 0" in capsys.readouterr().err and not out.exists()

    class Made(Exception):
        pass

    def section(spec, plan, out, models_dir, n_jobs=2, **kwargs):
        raise Made(n_jobs)

    monkeypatch.setattr(sections, "library_section", section)
    parser = argparse.ArgumentParser()
    add_report_arguments(parser)
    args = parser.parse_args(["--workers", "1", "--out", str(out), "--libraries", "synthetic", "--quick"])
    with pytest.raises(Made) as made:
        run_report(args)
    assert made.value.args == (1,)
