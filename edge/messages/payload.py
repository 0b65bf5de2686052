"""Validation shared by every superbody JSON message codec (``edge/messages/wire.py``, ``host/messages/pose.py``).

A codec's ``decode`` calls ``parse_json`` for the bytes, then ``check_message`` for the
schema, version and top-level fields, then the ``check_*`` functions for each value. All of them
raise ``DecodeError`` naming the field (``people[2].bbox[1]``), a ``reason`` from ``REASONS``
for reject counters, and the allowed range; each returns the value it checked. What differs
between codecs (the size limit, the schema name, the field lists) comes in as arguments.
"""

from __future__ import annotations

import json
import numbers
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final, Literal, NoReturn, get_args

import numpy as np
from numpy.typing import NDArray

from superbody.edge.site import NAME_RE

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "message_encoding",
    "int_within",
    "checked_json",
    "ROOT",
    "MAX_INT63",
    "REASONS",
    "Reason",
    "DecodeError",
    "fail",
    "brief",
    "join_path",
    "parse_json",
    "check_message",
    "check_object",
    "check_int",
    "check_int_pair",
    "check_name",
    "check_array",
    "check_array_max",
    "as_int",
    "NAME_PATTERN",
    "typed_input",
]

NAME_PATTERN: Final[str] = NAME_RE.pattern  # for the typed message definitions and their JSON Schemas
ROOT: Final[str] = "$"  # the field named by errors about the payload as a whole
MAX_INT63: Final[int] = 2**63 - 1  # sequence numbers and nanosecond stamps

Reason = Literal[
    "oversize",       # payload longer than the codec's MAX_PAYLOAD_BYTES
    "not_utf8",       # payload bytes are not UTF-8
    "not_json",       # not parseable JSON (including nesting too deep)
    "duplicate_key",  # an object repeats a key
    "type",           # wrong JSON type (a bool where a number goes, a string for an integer...)
    "missing",        # a required field is absent
    "unknown_field",  # a field this version does not define
    "length",         # an array of the wrong length, or too many entries (people, cameras)
    "range",          # a value outside its allowed range, or a broken constraint (x0 <= x1, sum)
    "format",         # a string not matching its pattern (site and camera names)
    "non_finite",     # NaN/Infinity literal, or a number that overflows to infinity
    "schema",         # "schema" is not the codec's SCHEMA
    "version",        # a version this decoder does not read
    "site",           # the site is not the subscriber's expected_site
]
REASONS: Final[frozenset[str]] = frozenset(get_args(Reason))


class DecodeError(ValueError):
    """A payload that is not a valid message of the codec that decoded it.

    Attributes:
        field: dotted path of the offending value, e.g. ``people[2].keypoints[5][1]``; ``$`` for
            the payload as a whole.
        reason: one of ``REASONS``, for counting rejects.
        detail: what was wrong and what is allowed.
    """

    def __init__(self, field: str, reason: Reason, detail: str) -> None:
        super().__init__(f"{field}: {detail}")
        self.field = field
        self.reason = reason
        self.detail = detail

    def __reduce__(self):  # pickle with all three arguments, not just the message
        return (type(self), (self.field, self.reason, self.detail))


def fail(field: str, reason: Reason, detail: str) -> NoReturn:
    """Raise ``DecodeError``; an empty ``field`` (the top-level object) is reported as ``$``."""
    raise DecodeError(field or ROOT, reason, detail)


def brief(value: Any) -> str:
    """A short description of a JSON value for error messages (never a deep repr)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value[:40] + "...") if len(value) > 40 else repr(value)
    if isinstance(value, list):
        return f"an array of {len(value)}"
    if isinstance(value, dict):
        return f"an object with {len(value)} keys"
    text = repr(value)
    return text if len(text) <= 40 else text[:40] + "..."


def join_path(path: str, key: str) -> str:
    """The path of ``key`` inside the object at ``path`` (``""`` is the top level); long keys cut to 40."""
    key = key if len(key) <= 40 else key[:40] + "..."
    return f"{path}.{key}" if path else key


# --- parsing -------------------------------------------------------------------------------


class _DuplicateKeys(dict):
    """A parsed object that repeated a key; reported with its path once the path is known."""

    __slots__ = ("duplicate",)
    duplicate: str  # the first repeated key


class _Constant(Exception):
    pass


def _object_pairs(pairs: list[tuple[str, Any]]) -> dict:
    obj = dict(pairs)
    if len(obj) == len(pairs):
        return obj
    seen: set[str] = set()
    for key, _ in pairs:
        if key in seen:
            break
        seen.add(key)
    dup = _DuplicateKeys(obj)
    dup.duplicate = key
    return dup


def _reject_constant(name: str) -> NoReturn:
    raise _Constant(name)


def parse_json(payload: Any, max_bytes: int) -> Any:
    """Size check, UTF-8, JSON: the parsed document, not yet validated.

    Args:
        payload: bytes, bytearray, memoryview or ``zenoh.ZBytes``.
        max_bytes: the codec's payload limit, checked before decoding anything.

    Returns:
        The document. An object that repeated a key is returned marked, and ``check_object``
        (or ``check_message``) reports it with its path.

    Raises:
        DecodeError: with field ``$`` and reason ``type``, ``oversize``, ``not_utf8``,
            ``non_finite`` (a NaN/Infinity literal) or ``not_json``.
    """
    if isinstance(payload, (bytes, bytearray)):
        size = len(payload)
    elif isinstance(payload, memoryview):
        size = payload.nbytes
    elif hasattr(payload, "to_bytes") and hasattr(payload, "__len__"):  # zenoh.ZBytes
        size = len(payload)
    else:
        fail(ROOT, "type", f"must be bytes, bytearray, memoryview or zenoh.ZBytes, got {type(payload).__name__}")
    if size > max_bytes:
        fail(ROOT, "oversize", f"is {size} bytes, more than the {max_bytes} allowed")
    if isinstance(payload, memoryview):
        data: memoryview | bytes | bytearray = payload if payload.c_contiguous else payload.tobytes()
    elif isinstance(payload, (bytes, bytearray)):
        data = payload
    else:
        data = payload.to_bytes()
    try:
        text = str(data, "utf-8")
    except UnicodeDecodeError as e:
        fail(ROOT, "not_utf8", f"is not UTF-8 (byte {e.start}: {e.reason})")
    try:
        return json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_object_pairs)
    except _Constant as e:
        fail(ROOT, "non_finite", f"contains the literal {e.args[0]}; numbers must be finite")
    except json.JSONDecodeError as e:
        fail(ROOT, "not_json", f"is not JSON ({e.msg} at line {e.lineno} column {e.colno})")
    except RecursionError:
        fail(ROOT, "not_json", "is nested too deeply to parse")
    except ValueError as e:  # e.g. an integer literal longer than Python's 4300-digit limit
        fail(ROOT, "not_json", f"is not parseable JSON ({str(e)[:80]})")


def typed_input(payload: Any, max_bytes: int) -> bytes | None:
    """The payload as bytes if a codec's typed decoder may take it on its own, else None.

    The typed decoders (msgspec) take what the reference encoders write: at most ``max_bytes``,
    pure ASCII, no backslash. With no escapes every ``"`` in valid JSON opens or closes a
    string, so a codec can rule out duplicate keys by counting quotes (msgspec keeps the last
    of two equal keys silently), and no string can hide a control character. Anything else
    (non-ASCII names, escapes, non-bytes) goes to the rule-by-rule validator, which decides
    exactly and names the field.
    """
    if type(payload) is bytes:
        data = payload
    elif isinstance(payload, (bytes, bytearray, memoryview)):
        data = bytes(payload)
    elif hasattr(payload, "to_bytes") and hasattr(payload, "__len__"):  # zenoh.ZBytes
        data = payload.to_bytes()
    else:
        return None
    if len(data) > max_bytes or not data.isascii() or b"\\" in data:
        return None
    return data


# --- validation ----------------------------------------------------------------------------


def check_message(doc: Any, schema: str, version: int | tuple[int, ...], fields: tuple[str, ...]) -> dict:
    """The top-level object: ``schema`` and ``version`` first, then exactly ``fields``.

    ``version`` is the version this decoder reads, or a tuple of the versions it reads.
    Schema and version are checked before the other fields, so a newer message is reported as
    such (reason ``schema`` or ``version``), not as unknown fields.
    """
    versions = version if isinstance(version, tuple) else (version,)
    reads = " or ".join(str(v) for v in versions)
    if not isinstance(doc, dict):
        fail(ROOT, "type", f"must be a JSON object, got {brief(doc)}")
    if isinstance(doc, _DuplicateKeys):
        fail(join_path("", doc.duplicate), "duplicate_key", "appears more than once in its object")
    if "schema" not in doc:
        fail("schema", "missing", f"is required and must be {schema!r}")
    if doc["schema"] != schema:
        fail("schema", "schema", f"must be {schema!r}, got {brief(doc['schema'])}")
    if "version" not in doc:
        fail("version", "missing", f"is required; this decoder reads version {reads}")
    got = doc["version"]
    if type(got) is not int:
        fail("version", "type", f"must be the integer {reads}, got {brief(got)}")
    if got not in versions:
        fail("version", "version", f"{got} is not supported; this decoder reads version {reads}")
    return check_object(doc, "", fields, label=f"{schema} version {got}")


def check_object(
    value: Any, path: str, required: tuple[str, ...], optional: tuple[str, ...] = (), *, label: str,
) -> dict:
    """An object with every ``required`` key, any of ``optional``, and nothing else.

    Args:
        label: the schema, for unknown-field errors, e.g. ``"superbody.observation version 1"``.
    """
    if not isinstance(value, dict):
        fail(path, "type", f"must be an object, got {brief(value)}")
    if isinstance(value, _DuplicateKeys):
        fail(join_path(path, value.duplicate), "duplicate_key", "appears more than once in its object")
    for key in value:
        if key not in required and key not in optional:
            allowed = ", ".join(required + optional)
            fail(join_path(path, key), "unknown_field", f"is not a field of {label}; allowed: {allowed}")
    for key in required:
        if key not in value:
            fail(join_path(path, key), "missing", "is required")
    return value


def check_int(value: Any, path: str, lo: int, hi: int) -> int:
    """A JSON integer (not a bool, not ``1.0``) in [lo, hi]."""
    if type(value) is not int:
        fail(path, "type", f"must be an integer in [{lo}, {hi}], got {brief(value)}")
    if not lo <= value <= hi:
        fail(path, "range", f"must be in [{lo}, {hi}], got {value}")
    return value


def check_int_pair(value: Any, path: str, lo: int, hi: int) -> tuple[int, int]:
    """Two JSON integers in [lo, hi], e.g. an image size."""
    check_array(value, path, 2, f"integers in [{lo}, {hi}]")
    return check_int(value[0], f"{path}[0]", lo, hi), check_int(value[1], f"{path}[1]", lo, hi)


def check_name(value: Any, path: str) -> str:
    """A site or camera name: ``edge.site.NAME_RE``, the characters safe in a Zenoh key."""
    if not isinstance(value, str):
        fail(path, "type", f"must be a string, got {brief(value)}")
    if not NAME_RE.fullmatch(value):
        fail(path, "format", f"must be 1-64 characters of letters, digits, '_' or '-', got {brief(value)}")
    return value


def check_array(value: Any, path: str, length: int, what: str) -> list:
    """An array of exactly ``length`` entries; ``what`` describes them in errors ("numbers in [0, 1]").

    Only the array is checked, not its entries.
    """
    if not isinstance(value, list):
        fail(path, "type", f"must be an array of {length} {what}, got {brief(value)}")
    if len(value) != length:
        fail(path, "length", f"must have {length} entries, has {len(value)}")
    return value


def check_array_max(value: Any, path: str, max_length: int, what: str) -> list:
    """An array of at most ``max_length`` entries; ``what`` names them in errors ("people").

    Only the array is checked, not its entries.
    """
    if not isinstance(value, list):
        fail(path, "type", f"must be an array of at most {max_length} {what}, got {brief(value)}")
    if len(value) > max_length:
        fail(path, "length", f"must have at most {max_length} entries, has {len(value)}")
    return value


# --- encoding ------------------------------------------------------------------------------


def as_int(value: Any) -> Any:
    """``value`` as a Python int if it is an integer (numpy's too), for ``json.dumps``.

    Encoders call this before validating their own document; anything else, bools included, is
    returned unchanged for the validation to reject with the field's name.
    """
    return int(value) if isinstance(value, numbers.Integral) and not isinstance(value, bool) else value


_NUMBER: Final[frozenset[type]] = frozenset({int, float})


def check_numbers(flat: list, where: Callable[[int], str]) -> NDArray[np.float64]:
    """Finite numbers as float64; ``where(k)`` names the k-th element in errors."""
    if not _NUMBER.issuperset(map(type, flat)):  # bools, strings, nulls, arrays, objects
        k = next(k for k, x in enumerate(flat) if type(x) not in _NUMBER)
        fail(where(k), "type", f"must be a number, got {brief(flat[k])}")
    try:
        a = np.array(flat, dtype=np.float64)
    except OverflowError:  # an integer beyond float64
        k = next(k for k, x in enumerate(flat) if type(x) is int and _overflows(x))
        fail(where(k), "non_finite", f"must be a finite number, got an integer of {len(str(abs(flat[k])))} digits")
    finite = np.isfinite(a)
    if not finite.all():  # 1e400 parses as inf
        k = int(np.argmin(finite))
        fail(where(k), "non_finite", f"must be a finite number, got {brief(flat[k])}")
    return a


def _overflows(x: int) -> bool:
    try:
        float(x)
    except OverflowError:
        return True
    return False


def check_range(
    a: NDArray[np.float64], lo: NDArray, hi: NDArray, where: Callable[[int], str], interval: Callable[[int], str],
    open_lo: NDArray[np.bool_] | bool = False,
) -> None:
    """Every ``a[..., c]`` in [lo[c], hi[c]] (or (lo[c], hi[c]] where ``open_lo[c]``); names the first element outside."""
    bad = (a < lo) | (a > hi) | (open_lo & (a <= lo))
    if bad.any():
        k = int(np.argmax(bad.ravel()))
        fail(where(k), "range", f"must be in {interval(k)}, got {a.ravel()[k]:g}")


def message_encoding(schema: str, version: int) -> zenoh.Encoding:
    """The ``zenoh.Encoding`` of a superbody message: JSON with ``<schema>/<version>`` (Zenoh 1.x
    renders it ``application/json;<schema>/<version>``, each codec's ``ENCODING``)."""
    import zenoh  # lazily: the codecs themselves do not need Zenoh

    return zenoh.Encoding.APPLICATION_JSON.with_schema(f"{schema}/{version}")


def checked_json(doc: dict, validate: Callable[[Any, str | None], object], what: str) -> bytes:
    """``doc`` as compact JSON, once the message's own validator takes it: a codec refuses to send
    what every subscriber would reject, and fails where the bug is.

    Raises:
        ValueError: ``cannot encode {what}: `` and the validator's ``DecodeError``.
    """
    try:
        validate(doc, None)
    except DecodeError as e:
        raise ValueError(f"cannot encode {what}: {e}") from e
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode("utf-8")


def int_within(value: Any, lo: int, hi: int) -> int | None:
    """``value`` as an int if it is an integer (numpy's too, not a bool) in [lo, hi], else None:
    the encoders' vectorised checks use it on the values they are about to send."""
    if type(value) is not int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            return None
        value = int(value)
    return value if lo <= value <= hi else None
