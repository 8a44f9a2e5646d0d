"""The FK micro-benchmark's command line (``python -m services.planner.fk_bench``)."""

from __future__ import annotations

import pytest

from services.planner import fk_bench


@pytest.mark.parametrize("device", ["cuda:99", "gpu"])
def test_a_device_this_machine_lacks_is_one_line_naming_the_option(device, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        fk_bench.main(["--device", device, "--n", "8", "--repeats", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2 and "--device" in err[-1] and repr(device) in err[-1]
    assert "Traceback" not in "\n".join(err)


@pytest.mark.parametrize(("args", "message"), [
    (["--repeats", "0"], "--repeats must be at least 1, got 0"),
    (["--n", "8", "0"], "--n: each batch size must be at least 1, got 0"),
    (["--threads", "-2"], "--threads must be >= 0 (0: torch's default), got -2"),
])
def test_bad_counts_are_one_line_naming_the_option(args, message, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        fk_bench.main(args)
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip() == f"python -m services.planner.fk_bench: error: {message}"
