"""``foresight bench host``: the stall statistics, the timing loop, the steal share and the command."""

from __future__ import annotations

import json
import math

import pytest

from tools import host_bench


def test_stall_stats_compare_the_slowest_runs_with_the_median():
    s = host_bench.stall_stats([10.0] * 98 + [30.0, 50.0])
    assert s["runs"] == 100 and s["p50_ms"] == 10.0 and s["max_ms"] == 50.0 and s["max_over_p50"] == 5.0
    assert s["over_2x"] == 2 and math.isclose(s["p99_over_p50"], s["p99_ms"] / 10.0) and 10.0 < s["p99_ms"] < 50.0
    assert host_bench.stall_stats([7.0])["p99_over_p50"] == 1.0


@pytest.mark.parametrize("bad", [[], [1.0, float("nan")], [0.0, 1.0], [-1.0]])
def test_stall_stats_refuse_what_is_no_duration(bad):
    with pytest.raises(ValueError, match="durations must be finite and positive"):
        host_bench.stall_stats(bad)


def test_time_work_times_each_call_after_an_untimed_one():
    ticks = iter([0.0, 0.010, 1.0, 1.030])
    calls = []
    ms = host_bench.time_work(lambda: calls.append(1), 2, clock=lambda: next(ticks))
    assert len(calls) == 3 and [round(m, 6) for m in ms] == [10.0, 30.0]


def test_steal_share_is_the_hosts_part_of_the_cpu_time_between_two_readings():
    before = [100, 0, 50, 800, 0, 0, 0, 10, 0, 0]
    after = [160, 0, 70, 810, 0, 0, 0, 20, 0, 0]  # 60 user, 20 system, 10 idle, 10 steal
    assert host_bench.steal_share(before, after) == 0.1
    assert host_bench.steal_share(None, after) is None and host_bench.steal_share(before[:5], after) is None
    assert host_bench.steal_share(before, before) == 0.0


def test_the_command_prints_both_workloads_and_refuses_a_bad_count(capsys):
    argv = ["--repeats", "3", "--products", "1", "--loop", "10"]
    assert host_bench.main([*argv, "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["repeats"] == 3 and r["torch"]["runs"] == 3 and r["python"]["runs"] == 3
    assert r["steal_share"] is None or 0.0 <= r["steal_share"] <= 1.0
    assert host_bench.main(argv) == 0
    out = capsys.readouterr().out
    assert "stall factor" in out and out.count("\n") >= 4
    with pytest.raises(SystemExit) as exit_:
        host_bench.main(["--repeats", "0"])
    assert exit_.value.code == 2 and "--repeats: must be 1 or more, got 0" in capsys.readouterr().err


def test_the_table_reads_where_the_machine_gives_no_load_average():
    stats = host_bench.stall_stats([10.0, 11.0, 30.0])
    r = {"repeats": 3, "threads": 1, "cpus": None, "load_avg_1min": None, "torch": stats, "python": stats,
         "steal_share": None}
    text = host_bench.format_bench(r)
    assert "(CPUs not known, load not known here)" in text
    assert "steal (CPU time the host took): not available here" in text
    assert "(2 usable CPUs, load 0.50)" in host_bench.format_bench({**r, "cpus": 2, "load_avg_1min": 0.5})


def test_stall_line_measures_the_machine_now_and_says_what_it_means():
    line = host_bench.stall_line(repeats=5, products=1)
    assert line.startswith("this machine's stall factor, measured now (5 runs of `foresight bench host`'s torch work")
    factor = float(line.split("work): ", 1)[1].split(" ", 1)[0])
    assert factor >= 1.0 and ("(a quiet machine" in line) == (factor < 1.5)


@pytest.mark.parametrize("threads", ["0", "1025", "100000000", "99999999999"])
def test_a_thread_count_torch_cannot_take_is_one_line(capsys, monkeypatch, threads):
    """--threads 100000000 segfaulted (rc 139) and 99999999999 raised a traceback, both inside torch."""
    monkeypatch.setattr(host_bench, "run_bench", lambda *a, **k: pytest.fail("ran with a bad --threads"))
    with pytest.raises(SystemExit) as exit_:
        host_bench.main(["--threads", threads])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and err.count("\n") == 0 and "--threads: must be 1 " in err and threads in err


def test_the_table_says_how_many_threads_ran_and_the_cpus_this_process_may_use(monkeypatch):
    """--threads 3 read "in one thread"; the CPUs were os.cpu_count(), not those of the affinity and quota."""
    monkeypatch.setattr(host_bench, "usable_cpus", lambda: 3, raising=False)
    monkeypatch.setattr(host_bench.os, "cpu_count", lambda: 16)
    r = host_bench.run_bench(repeats=2, products=1, loop=10, threads=2)
    assert r["cpus"] == 3
    head = host_bench.format_bench(r).splitlines()[0]
    assert head.startswith("the same work 2 times, torch on 2 threads and python on one (3 usable CPUs of 16, "), head
    assert host_bench.format_bench({**r, "threads": 1, "cpu_count": 3}).startswith(
        "the same work 2 times in one thread (3 usable CPUs, ")
