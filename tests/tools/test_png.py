"""tools/png.py: a PNG path is checked, its folder included, before the work that draws it."""

from __future__ import annotations

from pathlib import Path

import pytest

from shared.runtime import UserError
from tools.png import check_png


@pytest.mark.parametrize("path, text", [("", "--plot: empty"), ("top", "ending in .png"),
                                        ("top.jpg", "ending in .png")])
def test_a_name_that_would_not_be_the_png_named_is_refused(path: str, text: str) -> None:
    with pytest.raises(UserError, match=text):
        check_png(path, "--plot")


def test_a_folder_that_cannot_be_made_is_refused_before_any_work() -> None:
    """``--plot /proc/nope/x.png`` passed the check and failed once the work was done."""
    with pytest.raises(UserError) as exc:
        check_png("/proc/nope/x.png", "--plot")
    assert str(exc.value) == "/proc/nope: No such file or directory"


def test_a_file_in_the_way_of_the_folder_or_a_folder_at_the_path_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    with pytest.raises(UserError, match=r"f: a file is in the way \(a directory is needed there\)$"):
        check_png(str(tmp_path / "f" / "x.png"), "--out")
    (tmp_path / "d.png").mkdir()
    with pytest.raises(UserError, match="a directory is in the way"):
        check_png(str(tmp_path / "d.png"), "--out")


def test_a_new_folder_is_made_and_nothing_written(tmp_path: Path) -> None:
    out = tmp_path / "plots" / "deeper" / "x.png"
    check_png(str(out), "--out")
    assert out.parent.is_dir() and not out.exists()
