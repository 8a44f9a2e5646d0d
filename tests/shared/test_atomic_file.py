"""Files written whole: the old file or the new one, never half of one; the file in a path's way named."""

from __future__ import annotations

import os
import stat

import pytest

from shared.atomic_file import atomic_write, make_parent


def test_the_new_file_takes_the_name_only_when_complete(tmp_path):
    path = tmp_path / "sub" / "f.bin"
    with atomic_write(path) as f:
        f.write(b"first")
        assert not path.exists()  # still the temporary file
    assert path.read_bytes() == b"first" and stat.S_IMODE(path.stat().st_mode) == 0o644
    with pytest.raises(OSError), atomic_write(path) as f:
        f.write(b"second, cut short")
        raise OSError(28, "No space left on device")
    assert path.read_bytes() == b"first"
    assert [p.name for p in path.parent.iterdir()] == ["f.bin"]


def test_a_private_file_is_private_before_a_byte_is_written(tmp_path):
    with atomic_write(tmp_path / "k.key", mode=0o600, fsync=True) as f:
        assert stat.S_IMODE(os.fstat(f.fileno()).st_mode) == 0o600
        f.write(b"secret")
    assert stat.S_IMODE((tmp_path / "k.key").stat().st_mode) == 0o600


@pytest.mark.parametrize("below", ["x.npz", "d/x.npz"])
def test_a_file_in_the_way_is_named(tmp_path, below):
    (tmp_path / "afile").write_text("")
    with pytest.raises(NotADirectoryError) as exc:
        make_parent(tmp_path / "afile" / below)
    assert exc.value.filename == str(tmp_path / "afile") and "a file is in the way" in str(exc.value)


def test_unreadable_names_the_owner_and_mode_of_a_file_this_process_cannot_read(tmp_path, monkeypatch):
    from shared.atomic_file import unreadable

    f = tmp_path / "m.npz"
    f.write_bytes(b"x")
    f.chmod(0o640)
    assert unreadable(f) == ""
    monkeypatch.setattr("os.access", lambda *_a: False)  # root reads any file: another user's view, stood in for
    assert unreadable(f) == f"this process (uid {os.getuid()}) cannot read it (owner uid {f.stat().st_uid}, mode 640)"
