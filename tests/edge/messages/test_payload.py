"""Tests of the validation shared by the JSON message codecs (edge/messages/payload.py): tables of values
each helper accepts and rejects, with the field, reason and message it gives."""

from __future__ import annotations

import pickle
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from superbody.edge.messages.payload import (
    MAX_INT63,
    REASONS,
    ROOT,
    DecodeError,
    as_int,
    brief,
    check_array,
    check_array_max,
    check_int,
    check_int_pair,
    check_message,
    check_name,
    check_object,
    fail,
    join_path,
    parse_json,
)

LABEL = "superbody.test version 1"
FIELDS = ("schema", "version", "a")


def message(**change: Any) -> dict:
    """A valid top-level document for ``check_message(doc, "superbody.test", 1, FIELDS)``."""
    return {"schema": "superbody.test", "version": 1, "a": 0, **change}


# --- errors and messages -------------------------------------------------------------------


def test_decode_error_pickles_with_field_reason_and_detail() -> None:
    e = pickle.loads(pickle.dumps(DecodeError("people[0].x", "range", "must be in [0, 1], got 2")))
    assert (e.field, e.reason, e.detail, str(e)) == ("people[0].x", "range", "must be in [0, 1], got 2", "people[0].x: must be in [0, 1], got 2")
    assert isinstance(e, ValueError)


def test_fail_names_the_top_level_as_root() -> None:
    with pytest.raises(DecodeError) as info:
        fail("", "type", "must be a JSON object")
    assert info.value.field == ROOT == "$"


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (None, "null"),
        (True, "true"),                                 # a bool, not the integer 1
        ("cam", "'cam'"),
        ("x" * 50, repr("x" * 40 + "...")),             # long strings are cut
        ([1, 2, 3], "an array of 3"),                   # never the contents
        ({"a": 1}, "an object with 1 keys"),
        (1.5, "1.5"),
        (10**50, "1" + "0" * 39 + "..."),               # long numbers are cut
    ],
)
def test_brief(value: Any, text: str) -> None:
    assert brief(value) == text


@pytest.mark.parametrize(
    ("path", "key", "joined"),
    [
        ("", "seq", "seq"),                             # the top level has no prefix
        ("people[0]", "x", "people[0].x"),
        ("", "k" * 50, "k" * 40 + "..."),               # long keys are cut
    ],
)
def test_join_path(path: str, key: str, joined: str) -> None:
    assert join_path(path, key) == joined


# --- parse_json ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("payload", "parsed"),
    [
        (b'{"a": [1, 2.5, null]}', {"a": [1, 2.5, None]}),
        (bytearray(b"[]"), []),
        (memoryview(b'"x"'), "x"),
        (memoryview(b'[ 1 , 2 ]')[::2], [1, 2]),      # a non-contiguous view is copied
        (b" 1 ", 1),                                   # a scalar document, whitespace around it
    ],
)
def test_parse_json_accepts(payload: Any, parsed: Any) -> None:
    assert parse_json(payload, 64) == parsed


@pytest.mark.parametrize(
    ("payload", "reason", "detail"),
    [
        ("{}", "type", "must be bytes, bytearray, memoryview or zenoh.ZBytes, got str"),
        (b" " * 65, "oversize", "is 65 bytes, more than the 64 allowed"),   # checked before parsing
        (b"\xff", "not_utf8", "is not UTF-8 (byte 0: invalid start byte)"),
        (b"[NaN]", "non_finite", "contains the literal NaN; numbers must be finite"),
        (b"[-Infinity]", "non_finite", "contains the literal -Infinity; numbers must be finite"),
        (b"{", "not_json", "is not JSON (Expecting property name enclosed in double quotes at line 1 column 2)"),
        (b"", "not_json", "is not JSON (Expecting value at line 1 column 1)"),                        # empty
    ],
)
def test_parse_json_rejects(payload: Any, reason: str, detail: str) -> None:
    with pytest.raises(DecodeError) as info:
        parse_json(payload, 64)
    assert (info.value.field, info.value.reason, info.value.detail) == (ROOT, reason, detail)


def test_parse_json_rejects_deep_nesting() -> None:
    with pytest.raises(DecodeError) as info:
        parse_json(b"[" * 100_000, 1 << 20)
    assert info.value.reason == "not_json"


def test_duplicate_key_is_reported_with_its_path() -> None:
    doc = parse_json(b'{"p": {"x": 1, "x": 2}}', 64)
    with pytest.raises(DecodeError) as info:
        check_object(doc["p"], "people[3]", ("x",), label=LABEL)
    assert (info.value.field, info.value.reason) == ("people[3].x", "duplicate_key")


# --- check_message and check_object --------------------------------------------------------


@pytest.mark.parametrize(
    ("doc", "field", "reason", "detail"),
    [
        ([], ROOT, "type", "must be a JSON object, got an array of 0"),
        ({"a": 0}, "schema", "missing", "is required and must be 'superbody.test'"),
        (message(schema="superbody.other"), "schema", "schema", "must be 'superbody.test', got 'superbody.other'"),
        ({"schema": "superbody.test"}, "version", "missing", "is required; this decoder reads version 1"),
        (message(version=True), "version", "type", "must be the integer 1, got true"),     # bool is not int
        (message(version=2, b=0), "version", "version", "2 is not supported; this decoder reads version 1"),  # before unknown fields
        (message(b=0), "b", "unknown_field", f"is not a field of {LABEL}; allowed: schema, version, a"),
        ({"schema": "superbody.test", "version": 1}, "a", "missing", "is required"),
    ],
)
def test_check_message_rejects(doc: Any, field: str, reason: str, detail: str) -> None:
    with pytest.raises(DecodeError) as info:
        check_message(doc, "superbody.test", 1, FIELDS)
    assert (info.value.field, info.value.reason, info.value.detail) == (field, reason, detail)


def test_check_message_returns_the_document() -> None:
    doc = message()
    assert check_message(doc, "superbody.test", 1, FIELDS) is doc


@pytest.mark.parametrize(
    ("value", "field", "reason", "detail"),
    [
        ("x", "p", "type", "must be an object, got 'x'"),
        ({"a": 1, "c": 2}, "p.c", "unknown_field", f"is not a field of {LABEL}; allowed: a, b"),
        ({"b": 1}, "p.a", "missing", "is required"),                       # optional does not stand in
    ],
)
def test_check_object_rejects(value: Any, field: str, reason: str, detail: str) -> None:
    with pytest.raises(DecodeError) as info:
        check_object(value, "p", ("a",), ("b",), label=LABEL)
    assert (info.value.field, info.value.reason, info.value.detail) == (field, reason, detail)


@pytest.mark.parametrize("value", [{"a": 1}, {"a": 1, "b": 2}])  # optional field absent or present
def test_check_object_accepts(value: dict) -> None:
    assert check_object(value, "p", ("a",), ("b",), label=LABEL) is value


# --- scalars and arrays --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("check", "value", "field", "reason", "detail"),
    [
        (lambda v: check_int(v, "seq", 0, MAX_INT63), True, "seq", "type", f"must be an integer in [0, {MAX_INT63}], got true"),
        (lambda v: check_int(v, "seq", 0, 10), 1.0, "seq", "type", "must be an integer in [0, 10], got 1.0"),  # 1.0 is not 1
        (lambda v: check_int(v, "seq", 0, 10), -1, "seq", "range", "must be in [0, 10], got -1"),
        (lambda v: check_int_pair(v, "image", 16, 64), [16], "image", "length", "must have 2 entries, has 1"),
        (lambda v: check_int_pair(v, "image", 16, 64), {}, "image", "type", "must be an array of 2 integers in [16, 64], got an object with 0 keys"),
        (lambda v: check_int_pair(v, "image", 16, 64), [16, 65], "image[1]", "range", "must be in [16, 64], got 65"),
        (lambda v: check_name(v, "site"), 7, "site", "type", "must be a string, got 7"),
        (lambda v: check_name(v, "site"), "lab/1", "site", "format", "must be 1-64 characters of letters, digits, '_' or '-', got 'lab/1'"),
        (lambda v: check_name(v, "site"), "", "site", "format", "must be 1-64 characters of letters, digits, '_' or '-', got ''"),  # empty
        (lambda v: check_array(v, "bbox", 4, "numbers"), None, "bbox", "type", "must be an array of 4 numbers, got null"),
        (lambda v: check_array(v, "bbox", 4, "numbers"), [], "bbox", "length", "must have 4 entries, has 0"),  # empty
        (lambda v: check_array_max(v, "people", 2, "people"), "ab", "people", "type", "must be an array of at most 2 people, got 'ab'"),
        (lambda v: check_array_max(v, "people", 2, "people"), [1, 2, 3], "people", "length", "must have at most 2 entries, has 3"),
    ],
)
def test_checks_reject(check: Callable[[Any], Any], value: Any, field: str, reason: str, detail: str) -> None:
    with pytest.raises(DecodeError) as info:
        check(value)
    assert (info.value.field, info.value.reason, info.value.detail) == (field, reason, detail)
    assert info.value.reason in REASONS


@pytest.mark.parametrize(
    ("check", "value", "result"),
    [
        (lambda v: check_int(v, "seq", 0, MAX_INT63), MAX_INT63, MAX_INT63),   # inclusive bound
        (lambda v: check_int_pair(v, "image", 16, 64), [16, 64], (16, 64)),
        (lambda v: check_name(v, "camera"), "cam_1-A", "cam_1-A"),
        (lambda v: check_array(v, "bbox", 2, "numbers"), ["not", "checked"], ["not", "checked"]),  # entries are the caller's
        (lambda v: check_array_max(v, "people", 2, "people"), [], []),          # empty
    ],
)
def test_checks_accept(check: Callable[[Any], Any], value: Any, result: Any) -> None:
    assert check(value) == result


# --- encoding ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (np.int64(7), 7),                               # numpy integers become Python ints
        (np.uint8(255), 255),
        (True, True),                                   # bools are left for validation to reject
        (1.5, 1.5),
        ("3", "3"),
    ],
)
def test_as_int(value: Any, expected: Any) -> None:
    out = as_int(value)
    assert out == expected and type(out) is type(expected)
