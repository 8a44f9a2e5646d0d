"""A log this build cannot read: every message refused for its schema version, none decoded."""

from __future__ import annotations

from collections.abc import Sequence

from shared.protocol import ProtocolError
from shared.runtime import UserError

__all__ = ["check_readable"]


def check_readable(decoded: int, refused: Sequence[ProtocolError], what: str = "message(s)") -> None:
    """Raise :class:`UserError` when nothing was decoded and every refusal was for the schema version.

    Another build's log, not an empty run: the log tools said "no plans" or printed a table of zeros for it.

    Args:
        decoded: Messages decoded.
        refused: Why each message was refused.
        what: What they are, for the sentence (``"Plan message(s)"``).
    """
    if not decoded and refused and all(e.reason == "version" for e in refused):
        raise UserError(f"its {len(refused)} {what} are of a schema version this build does not read ({refused[0]})")
