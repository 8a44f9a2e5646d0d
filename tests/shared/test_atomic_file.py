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


def test_a_pipe_or_a_directory_at_the_path_is_refused_and_left_alone(tmp_path):
    """A rename onto a device or a pipe replaced it with a regular file: `foresight log compress X /dev/null` as root
    left the machine without its /dev/null (a review; a FIFO stands in for the device here)."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    (tmp_path / "dir").mkdir()
    ran = []
    with pytest.raises(FileExistsError) as exc, atomic_write(fifo) as f:
        ran.append(f)
    assert not ran and exc.value.filename == str(fifo) and "a named pipe (FIFO) is there" in exc.value.strerror
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and sorted(p.name for p in tmp_path.iterdir()) == ["dir", "pipe"]
    with pytest.raises(IsADirectoryError) as exc, atomic_write(tmp_path / "dir") as f:
        ran.append(f)
    assert not ran and exc.value.filename == str(tmp_path / "dir")


def test_a_pipe_made_while_the_file_is_written_is_not_replaced(tmp_path):
    path = tmp_path / "out.bin"
    with pytest.raises(FileExistsError), atomic_write(path) as f:
        f.write(b"data")
        os.mkfifo(path)
    assert stat.S_ISFIFO(os.lstat(path).st_mode) and [p.name for p in tmp_path.iterdir()] == ["out.bin"]


def test_a_symbolic_link_is_replaced_itself_and_its_target_left_alone(tmp_path):
    target, link = tmp_path / "target.bin", tmp_path / "link.bin"
    target.write_bytes(b"old")
    link.symlink_to(target)
    with atomic_write(link) as f:
        f.write(b"new")
    assert not link.is_symlink() and link.read_bytes() == b"new" and target.read_bytes() == b"old"
