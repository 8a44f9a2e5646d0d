"""The one check of a PNG output path, made before any work.

Used by ``foresight log snapshot --out`` and ``render --out``, ``library generate --plot``,
``foresight experiments ... --plot`` and ``python -m tools.reach --out``.
"""

from __future__ import annotations

from pathlib import Path

from shared.atomic_file import ready_to_write
from shared.runtime import UserError

__all__ = ["check_png"]


def check_png(path: str, option: str, make_folder: bool = True) -> None:
    """Refuse a plot path that would not become the PNG named, before the work that draws it.

    Its folder is made here (as writing it would) and must be writable: ``--plot /proc/nope/x.png`` failed only
    once the work was done. Nothing is written to the file itself.

    Args:
        path: The path given on the command line.
        option: The option's name, for the message (``--out``).
        make_folder: False: make nothing (the caller makes the folder just before it writes, and a command that
            fails first leaves none behind); a file in the way of the folder is refused all the same.

    Raises:
        UserError: ``path`` is empty (the current directory) or does not end in ``.png`` (matplotlib would
            refuse the format, or add ``.png`` to a name without one); its folder cannot be made or written
            to; a directory is at ``path``.
    """
    if not path.strip():
        raise UserError(f"{option}: empty; give the PNG file to write")
    if Path(path).suffix.lower() != ".png":
        raise UserError(f"{option} {path!r}: the plot is a PNG; give a file name ending in .png")
    if not make_folder:
        if Path(path).is_dir():
            raise UserError(f"{path}: a directory is in the way (a file is to be written there)")
        for above in Path(path).parents:  # the nearest that exists: a directory
            if above.exists():
                if not above.is_dir():
                    raise UserError(f"{above}: a file is in the way (a directory is needed there)")
                return
        return
    try:
        ready_to_write(path)
    except OSError as exc:
        # the words of every other output path's check (shared.atomic_file, cli_errors): the culprit named
        raise UserError(f"{exc.filename or path}: {exc.strerror or exc}") from None
