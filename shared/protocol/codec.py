"""Encoding and decoding: msgpack maps, arrays as dtype + shape + raw little-endian bytes.

:func:`decode` validates everything (type, version, field presence, scalar types, array dtypes,
shapes and finiteness, and per-message invariants) and raises :class:`ProtocolError`, whose message
names the offending field; :func:`encode` runs the same validation on what it produced, so bad data
never leaves.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from typing import Any, TypeVar

import msgpack
import numpy as np

from .limits import AXIS_LIMITS, MAX_CLASSES, MAX_GOALS, MAX_KEYPOINTS, MAX_PAYLOAD_BYTES, MAX_STRING_CHARS
from .messages import MESSAGE_TYPES
from .schema import READABLE_VERSIONS, SCHEMA_VERSION, ArraySpec, Message, ProtocolError
from .schema import field_error as _err

__all__ = ["encode", "decode", "written_version"]

M = TypeVar("M", bound=Message)

_MAX_LIST = max(MAX_CLASSES, MAX_GOALS, MAX_KEYPOINTS)
"""Longest msgpack array of a message: its string lists (names of M classes, K goals, J keypoints)."""
_MAX_MAP = 64
"""Most keys of a msgpack map: three times the largest message's fields, so a few unknown fields are still
named as such (a sender of a newer schema) rather than refused as malformed msgpack."""
_MAX_ITEMS = 4096
"""Most elements, over all msgpack maps and arrays of one payload (a message has about 20 plus its names).

msgpack builds every object before a field can be checked: without this bound, 16 MiB of one-byte empty maps
would become 16 million Python objects (about 1.2 GB) before the message is refused."""


class _TooMany(ValueError):
    """A msgpack container, or all of them together, over its bound: the message is too large."""


class _ItemBudget:
    """Counts the elements of the containers msgpack builds for one payload; raises past :data:`_MAX_ITEMS`."""

    def __init__(self) -> None:
        self.left = _MAX_ITEMS

    def take(self, items: Any) -> Any:
        self.left -= len(items) + 1
        if self.left < 0:
            raise _TooMany(f"more than {_MAX_ITEMS} msgpack objects")
        return items



def _unpack(data: bytes) -> Any:
    """The msgpack object tree of ``data``, every container bounded before it is built."""
    budget = _ItemBudget()
    return msgpack.unpackb(data, raw=False, strict_map_key=True, max_str_len=4 * MAX_STRING_CHARS,
                           max_bin_len=MAX_PAYLOAD_BYTES, max_array_len=_MAX_LIST, max_map_len=_MAX_MAP,
                           max_ext_len=0, list_hook=budget.take, object_hook=budget.take)


def _unpack_error(exc: Exception) -> ProtocolError:
    """What :func:`_unpack` raising ``exc`` means: a bound passed (too-large), an ext type or bad bytes (malformed)."""
    text = str(exc)
    if "exceeds max_ext_len" in text:  # max_ext_len=0: any ext type (a timestamp too) is refused by size
        return ProtocolError("message: not valid msgpack (msgpack ext types are not allowed)", "malformed")
    if isinstance(exc, _TooMany) or (isinstance(exc, ValueError) and "exceeds max_" in text):
        return ProtocolError(f"message: too many msgpack objects ({type(exc).__name__}: {text[:120]})", "too-large")
    if not text:  # msgpack raises these two without a text
        text = ("a byte that starts no msgpack object" if isinstance(exc, msgpack.FormatError)
                else "nested deeper than msgpack's limit" if isinstance(exc, msgpack.StackError) else "no detail")
    return ProtocolError(f"message: not valid msgpack ({type(exc).__name__}: {text[:120]})", "malformed")


@dataclasses.dataclass(frozen=True)
class _Field:
    """One field of a message class, with what encoding and decoding it needs resolved once."""

    name: str
    spec: ArraySpec | None  # an array field's spec, None for a scalar
    hint: Any  # the scalar's type (float, int, bool, str, list[str])
    want: np.dtype | None  # the array's dtype, and as it travels (little-endian: what encode writes)
    wire: np.dtype | None
    since: int = 1  # the schema version that added the field (shared.protocol.schema.added)
    default: Any = None  # its value in a message of an earlier version


@functools.cache
def _layout(cls: type, version: int = SCHEMA_VERSION) -> tuple[tuple[_Field, ...], frozenset[str]]:
    """A message class's fields and every key its payload of ``version`` may hold (resolved once per version)."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        spec = f.metadata.get("array")
        want = np.dtype(spec.dtype) if spec is not None else None
        out.append(_Field(f.name, spec, hints[f.name], want, want.newbyteorder("<") if want is not None else None,
                          f.metadata.get("since", 1), None if f.default is dataclasses.MISSING else f.default))
    return tuple(out), frozenset({"_type", "_v", *(f.name for f in out if f.since <= version)})


def written_version(msg: Message) -> int:
    """The lowest schema version that holds ``msg``: what :func:`encode` writes as its ``_v``.

    A field :func:`~shared.protocol.schema.added` later counts only when it is off its default (a version-1 reader
    takes the default), and so does a value a later version added (:meth:`Message.since`: a ``lost`` marker).
    Before, every message was written at :data:`SCHEMA_VERSION`: a build that reads version 1 refused every message
    of a newer one, a ``HumanPose`` or a ``Plan`` as much as the ``ClassPosterior`` whose fields had changed, so a
    system upgraded one machine at a time stopped at the first.
    """
    version = msg.since()
    for f in _layout(type(msg))[0]:
        if f.since > version and f.spec is None and getattr(msg, f.name) != f.default:
            version = f.since
    return version


def encode(msg: Message) -> bytes:
    """Encode a message to msgpack bytes (validating it first, so bad data never leaves).

    Raises:
        ProtocolError: If the message does not satisfy its own schema.
    """
    version = written_version(msg)
    out: dict[str, Any] = {"_type": msg.TYPE, "_v": version}
    for f in _layout(type(msg))[0]:
        if f.since > version:  # at its default: the version written did not have it
            continue
        value = getattr(msg, f.name)
        if f.wire is not None:
            src = np.asarray(value)
            arr = np.ascontiguousarray(src, dtype=f.wire)
            if arr.dtype.kind in "iub" and arr.size == src.size and not np.array_equal(arr.ravel(), src.ravel()):
                i = int(np.flatnonzero(arr.ravel() != src.ravel())[0])  # wrapped, truncated or not 0/1
                raise _err(msg.TYPE, f.name, f"{src.ravel()[i].item()!r} does not fit {f.want} (it would be "
                           f"sent as {arr.ravel()[i].item()!r})", "malformed")
            out[f.name] = {"dtype": arr.dtype.str, "shape": list(arr.shape), "data": arr.tobytes()}
        elif isinstance(value, np.generic):
            out[f.name] = value.item()
        else:
            out[f.name] = value
    try:
        data = msgpack.packb(out, use_bin_type=True)
    except (OverflowError, UnicodeEncodeError, ValueError, TypeError) as exc:  # 2**70, a lone surrogate
        raise ProtocolError(f"{msg.TYPE}: cannot be encoded ({type(exc).__name__}: {str(exc)[:120]})",
                            "malformed") from None
    decode(data, type(msg))  # one validation path for both directions
    return data


def _decode_array(t: str, f: _Field, raw: Any, dims: dict[str, int]) -> np.ndarray:
    name, spec, want, dtype = f.name, f.spec, f.want, f.wire  # dtype: what encode writes; nothing else is parsed
    assert spec is not None and want is not None and dtype is not None
    if not isinstance(raw, dict) or raw.keys() != _ARRAY_KEYS:
        raise _err(t, name, "array must be a map with keys dtype, shape, data", "malformed")
    if not isinstance(raw["dtype"], str):
        raise _err(t, name, f"dtype must be a string, got {type(raw['dtype']).__name__}", "malformed")
    if raw["dtype"] != dtype.str:  # (numpy's parser is no validator)
        raise _err(t, name, f"dtype {raw['dtype'][:16]!r} where {dtype.str!r} ({want.name}) is required", "shape")
    shape = raw["shape"]
    if not isinstance(shape, list) or not all(type(s) is int and s >= 0 for s in shape):  # int, not bool
        raise _err(t, name, f"shape {str(shape)[:80]} is not a list of non-negative ints", "malformed")
    if len(shape) != len(spec.shape):
        raise _err(t, name, f"shape {tuple(shape)} has {len(shape)} axes, expected {len(spec.shape)} "
                   f"{spec.shape}", "shape")
    for axis, (got, exp) in enumerate(zip(shape, spec.shape, strict=True)):
        if isinstance(exp, int):
            if got != exp:
                raise _err(t, name, f"shape {tuple(shape)} axis {axis} must be {exp}", "shape")
        elif got > AXIS_LIMITS[exp]:  # bounded before any product or allocation
            raise _err(t, name, f"shape {tuple(shape)} axis {axis} ({exp}) exceeds the limit "
                       f"{AXIS_LIMITS[exp]}", "too-large")
        elif exp in dims and dims[exp] != got:
            raise _err(t, name, f"shape {tuple(shape)} axis {axis} ({exp}) must be {dims[exp]} "
                       "like the other fields", "shape")
        else:
            dims[exp] = got
    data = raw["data"]
    if not isinstance(data, bytes | bytearray):
        raise _err(t, name, "data must be bytes", "malformed")
    n = math.prod(shape)  # exact (Python ints); every axis is bounded above
    if len(data) != n * dtype.itemsize:
        raise _err(t, name, f"data has {len(data)} bytes, shape {tuple(shape)} of {dtype.name} needs "
                   f"{n * dtype.itemsize}", "shape")
    if dtype.kind == "b" and any(b > 1 for b in bytes(data)):  # numpy keeps byte 200 as True, sent on unchanged
        raise _err(t, name, "a bool is the byte 0 or 1", "malformed")
    arr = np.frombuffer(data, dtype=dtype).reshape(shape).astype(want, copy=True)
    if spec.finite and want.kind == "f" and not np.isfinite(arr).all():
        raise _err(t, name, "contains NaN or infinity", "non-finite")
    return arr


_ARRAY_KEYS = frozenset({"dtype", "shape", "data"})


def _check_scalar(t: str, name: str, tp: Any, value: Any) -> Any:
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _err(t, name, f"expected a number, got {type(value).__name__}", "malformed")
        value = float(value)  # msgpack ints are at most 2^64: always a finite float
        if not math.isfinite(value):
            raise _err(t, name, f"must be finite, got {value}", "non-finite")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _err(t, name, f"expected an integer, got {type(value).__name__}", "malformed")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _err(t, name, f"expected a boolean, got {type(value).__name__}", "malformed")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _err(t, name, f"expected a string, got {type(value).__name__}", "malformed")
        if len(value) > MAX_STRING_CHARS:
            raise _err(t, name, f"string of {len(value)} characters exceeds the limit {MAX_STRING_CHARS}",
                       "too-large")
        return value
    if typing.get_origin(tp) is list:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise _err(t, name, "expected a list of strings", "malformed")
        if any(len(v) > MAX_STRING_CHARS for v in value):
            raise _err(t, name, f"an entry exceeds the limit of {MAX_STRING_CHARS} characters", "too-large")
        return list(value)
    raise _err(t, name, f"unsupported field type {tp!r}")  # pragma: no cover


def decode(data: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate msgpack bytes into a message.

    Args:
        data: The payload.
        expected: If given, the message must be of this type.

    Returns:
        The message dataclass instance.

    Raises:
        ProtocolError: On a payload over :data:`~shared.protocol.limits.MAX_PAYLOAD_BYTES`,
            truncated/malformed bytes, unknown type, wrong version, a missing or ill-typed field, a
            declared size over its limit, wrong dtype or shape, non-finite values or a broken
            invariant; its ``reason`` says which (:data:`~shared.protocol.schema.REASONS`).
    """
    if len(data) > MAX_PAYLOAD_BYTES:
        raise ProtocolError(f"message: {len(data)} bytes exceed the limit of {MAX_PAYLOAD_BYTES}", "too-large")
    try:
        raw = _unpack(bytes(data))
    except Exception as exc:  # msgpack raises several unrelated types for bad input
        raise _unpack_error(exc) from None
    if not isinstance(raw, dict):
        raise ProtocolError(f"message: expected a map, got {type(raw).__name__}")
    t = raw.get("_type")
    if not isinstance(t, str) or t not in MESSAGE_TYPES:
        raise ProtocolError(f"message._type: unknown message type {str(t)[:80]!r}", "wrong-type")
    cls = MESSAGE_TYPES[t]
    if expected is not None and cls is not expected:
        raise ProtocolError(f"message._type: got {t}, expected {expected.TYPE}", "wrong-type")
    version = raw.get("_v")
    if type(version) is not int or version not in READABLE_VERSIONS:  # not True, not 1.0
        raise ProtocolError(f"{t}._v: schema version {str(version)[:40]!r}, this build speaks {SCHEMA_VERSION} "
                            f"and reads {', '.join(map(str, READABLE_VERSIONS))}", "version")
    fields, known = _layout(cls, version)
    unknown = raw.keys() - known
    if unknown:
        names = sorted(unknown, key=repr)  # str and bytes keys: sorting them together was a TypeError
        raise ProtocolError(f"{t}: unknown field(s) {', '.join(repr(k[:40]) for k in names[:5])}", "malformed")
    kwargs: dict[str, Any] = {}
    dims: dict[str, int] = {}
    for f in fields:
        if f.name not in raw:
            if f.since > version:  # added after the sender's version: it did not know the field
                kwargs[f.name] = f.default
                continue
            raise _err(t, f.name, "missing", "malformed")
        if f.spec is not None:
            kwargs[f.name] = _decode_array(t, f, raw[f.name], dims)
        else:
            kwargs[f.name] = _check_scalar(t, f.name, f.hint, raw[f.name])
    msg = cls(**kwargs)
    msg.check()
    if version < SCHEMA_VERSION:
        msg.check_version(version)
    return msg  # type: ignore[return-value]
