"""services.demo_inputs: the demo's scene, library and human class are checked before anything heavy is imported."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from services.demo import DemoConfig
from services.demo_inputs import check_inputs, human_label
from shared.config import ConfigError
from shared.runtime import UserError
from shared.synthetic import generate_library

REPO = Path(__file__).resolve().parents[2]

FIRST_ERROR = """
import sys
from services import demo
try:
    demo.main(sys.argv[1:])
except SystemExit as exc:
    print(exc.code, *sorted(m for m in ("torch", "matplotlib", "services.planner.core") if m in sys.modules))
"""


@pytest.mark.parametrize("args", [["--human-class", "red_cu"], ["--scene", "nonsense"], ["--goals", "blue"],
                                  ["--library", "/nonexistent/library"]])
def test_a_misspelt_input_is_refused_before_the_planner_torch_or_matplotlib_is_imported(args: list[str]) -> None:
    """A newcomer's review: each was refused after 8-10 s, the time the demo took to import them first."""
    done = subprocess.run([sys.executable, "-c", FIRST_ERROR, *args], cwd=REPO, capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.split() == ["2"], (done.stdout, done.stderr[-2000:])
    assert "foresight demo: error:" in done.stderr


def test_the_synthetic_library_s_classes_are_known_without_generating_it(monkeypatch) -> None:
    monkeypatch.setattr("shared.synthetic.generate_library", lambda *a, **k: pytest.fail("generated (2 s)"))
    with pytest.raises(UserError, match=r"--human-class 'red_cu': not a class of the synthetic library .*"
                                        r"did you mean red_cup\?"):
        check_inputs(DemoConfig(human_class="red_cu"))
    check_inputs(DemoConfig(human_class="far_left"))
    with pytest.raises(ConfigError, match="demo.goals: 'blue' not a cup of scene"):
        check_inputs(DemoConfig(goals="blue"))


def test_the_early_check_knows_the_classes_the_run_generates() -> None:
    names = list(generate_library(seed=0).class_names)
    assert [human_label(names, n, "s") for n in names] == list(range(len(names)))
    for name in names:
        check_inputs(DemoConfig(human_class=name))
