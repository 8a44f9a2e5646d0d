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
