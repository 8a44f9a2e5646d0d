"""The building blocks of a message schema: the base class, array fields, the schema version.

A message type is a dataclass deriving from :class:`Message` with a ``TYPE`` name; scalar fields are
``float``, ``int``, ``bool``, ``str`` or ``list[str]``; array fields are declared with :func:`array`
(dtype, shape with fixed sizes or symbols shared across the fields of one message, finiteness).
:meth:`Message.check` adds per-message invariants. Every error is a :class:`ProtocolError` whose
text starts with ``Type.field:``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

__all__ = ["SCHEMA_VERSION", "READABLE_VERSIONS", "REASONS", "ProtocolError", "ArraySpec", "array", "added", "Message",
           "field_error"]

SCHEMA_VERSION = 2
"""This build's schema version: 2 added ``ClassPosterior.familiar`` and ``.familiarity`` and the ``DemoMarker`` event
``lost``. A message is written with the lowest version that holds it (``codec.written_version``)."""
READABLE_VERSIONS = (1, 2)
"""Versions a receiver decodes: a field :func:`added` after a message's version takes its default (a version-1
``ClassPosterior`` is familiar), and must not be in its payload."""

REASONS: dict[str, str] = {
    # decoding (shared.protocol.codec, Message.check)
    "too-large": "the payload, or a size it declares, exceeds a limit of shared.protocol.limits",
    "malformed": "not msgpack, not a map, a missing or ill-typed field, an array that is not {dtype, shape, data}",
    "wrong-type": "an unknown message type, or another type than the key carries",
    "version": "another schema version",
    "shape": "a dtype, shape or data length that does not match the field or the other fields",
    "non-finite": "NaN or infinity where the field must be finite",
    "invariant": "a broken per-message invariant (an index out of its range, names that do not match, ...)",
    # receipt (shared.protocol.validation)
    "out-of-range": "a value outside its meaning (probability, geometry, period, feature, counter)",
    "joint-limits": "a joint position outside the receiver's joint limits plus the tolerance",
    "velocity": "a joint velocity above the receiver's velocity limits plus the tolerance",
    "stamp-future": "a stamp ahead of the receiver's clock (or a tick ahead of the lock-step clock)",
    "stamp-past": "a stamp older than the tolerance, or not the time of its tick in lock-step",
    "tick-order": "a tick lower than the same sender's previous one on that key",
    "sequence-order": "a sequence number (demo_id, index, step) not after the same sender's previous one",
    "mismatch": "not what the receiver is built for (its robot's joints, its scene's grid, its classes)",
}
"""Why a message is rejected: each :class:`ProtocolError` carries one of these keys as ``reason``."""


class ProtocolError(ValueError):
    """A message failed to decode or validate; the text names the offending field.

    Attributes:
        reason: One key of :data:`REASONS` (what rejections are counted by).
    """

    def __init__(self, text: str, reason: str = "malformed") -> None:
        super().__init__(text)
        self.reason = reason if reason in REASONS else "malformed"


@dataclass(frozen=True)
class ArraySpec:
    """Expected dtype and shape of an array field.

    Attributes:
        dtype: numpy dtype name, e.g. ``"float64"``; the wire dtype must match exactly.
        shape: One entry per axis: an int (fixed), or a symbol such as ``"K"`` that must take the same
            value in every field of the message where it appears.
        finite: Reject NaN and infinities (float dtypes only).
    """

    dtype: str
    shape: tuple[int | str, ...]
    finite: bool = True


def array(dtype: str, *shape: int | str, finite: bool = True) -> Any:
    """Declare an array field of a message dataclass."""
    return dataclasses.field(metadata={"array": ArraySpec(dtype, tuple(shape), finite)})


def added(version: int, default: Any) -> Any:
    """Declare a scalar field added in schema ``version``: a message of an earlier version has it at ``default``."""
    return dataclasses.field(default=default, metadata={"since": version})


class Message:
    """Base of all message dataclasses. Subclasses set ``TYPE`` and may override :meth:`check`."""

    TYPE: ClassVar[str] = ""

    def check(self) -> None:
        """Per-message invariants beyond field types and shapes; raise ProtocolError."""

    def check_version(self, version: int) -> None:
        """Values a message of schema ``version`` (older than this build's) cannot hold; raise ProtocolError."""

    def since(self) -> int:
        """The first schema version that holds this message's values (its added fields: ``codec.written_version``)."""
        return 1


def field_error(msg_type: str, field: str, text: str, reason: str = "invariant") -> ProtocolError:
    """The error for ``msg_type.field``: ``ProtocolError("Type.field: text", reason)``."""
    return ProtocolError(f"{msg_type}.{field}: {text}", reason)
