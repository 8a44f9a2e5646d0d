"""``foresight bench soak`` and ``faults`` say in their help that they are system checks, not speed benchmarks."""

from __future__ import annotations

import pytest

from tools import faults, soak


@pytest.mark.parametrize(("module", "name"), [(soak, "soak"), (faults, "faults")])
def test_the_help_says_it_is_a_system_check_with_no_baseline(module, name, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        module.main(["--help"], prog=f"foresight bench {name}")
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "A system check, not a speed benchmark: it runs no baseline to compare with and prints no ratio" in text
