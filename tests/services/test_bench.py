"""``foresight bench``: the list of benchmarks and the dispatch to each one's own command."""

from __future__ import annotations

from services.bench import BENCHES, main


def test_the_list_of_benchmarks_keeps_its_columns(capsys) -> None:
    """'tracker-live' and 'separation' ran into their descriptions at a fixed width of 10."""
    assert main(["--help"]) == 0
    rows = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("  ") and ln.split()[0] in BENCHES]
    assert len(rows) == len(BENCHES)
    starts = {ln.index(BENCHES[ln.split()[0]][1]) for ln in rows}
    assert len(starts) == 1 and min(ln.index(" ", 2) for ln in rows) < starts.pop() - 1


def test_an_unknown_benchmark_is_one_line(capsys) -> None:
    assert main(["nonsense"]) == 2
    assert capsys.readouterr().err.strip() == (
        f"foresight bench: error: unknown benchmark 'nonsense' (choose from {', '.join(BENCHES)})")


def test_no_benchmark_named_is_an_error_on_stderr(capsys) -> None:
    """The list went to stdout with exit status 2."""
    assert main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: foresight bench {") and "benchmarks:" in err
