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

__all__ = ["SCHEMA_VERSION", "ProtocolError", "ArraySpec", "array", "Message", "field_error"]

SCHEMA_VERSION = 1


class ProtocolError(ValueError):
    """A message failed to decode or validate; the text names the offending field."""


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


class Message:
    """Base of all message dataclasses. Subclasses set ``TYPE`` and may override :meth:`check`."""

    TYPE: ClassVar[str] = ""

    def check(self) -> None:
        """Per-message invariants beyond field types and shapes; raise ProtocolError."""


def field_error(msg_type: str, field: str, text: str) -> ProtocolError:
    """The error for ``msg_type.field``: ``ProtocolError("Type.field: text")``."""
    return ProtocolError(f"{msg_type}.{field}: {text}")
