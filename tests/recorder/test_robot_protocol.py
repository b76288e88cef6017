"""Khepera ASCII protocol: encode/parse round trips and typed errors."""

from __future__ import annotations

import string

import pytest
from hypothesis import given
from hypothesis import strategies as st

from data_schemas.errors import RobotError
from recorder.robot.errors import GarbledReply, RobotProtocolError
from recorder.robot.protocol import (
    Reply,
    Request,
    encode_reply,
    encode_request,
    int_fields,
    parse_reply,
    parse_request,
)

upper = st.sampled_from(string.ascii_uppercase)
reply_upper = upper.filter(lambda c: c != "Z")  # z is the protocol-error reply
ints = st.lists(st.integers(-(2**31), 2**31 - 1), max_size=6)
field_text = st.text(alphabet=[c for c in map(chr, range(0x20, 0x7F)) if c != ","], max_size=8)


@given(upper, ints)
def test_request_round_trip(letter: str, args: list[int]) -> None:
    line = encode_request(letter, *args)
    assert line.endswith(b"\r") and line.count(b"\r") == 1
    assert parse_request(line) == Request(letter, tuple(args))


@given(reply_upper, st.lists(field_text, max_size=6))
def test_reply_round_trip(letter: str, fields: list[str]) -> None:
    line = encode_reply(letter.lower(), *fields)
    assert line.endswith(b"\r\n")
    assert parse_reply(line, letter) == Reply(letter.lower(), tuple(fields))


@given(reply_upper, ints)
def test_int_fields_round_trip(letter: str, values: list[int]) -> None:
    reply = parse_reply(encode_reply(letter.lower(), *values), letter)
    assert int_fields(reply, len(values)) == tuple(values)


def test_known_lines() -> None:
    assert encode_request("D", 10, -10) == b"D,10,-10\r"
    assert encode_request("H") == b"H\r"
    assert parse_reply(b"b,5.02,5.01\r\n", "B").fields == ("5.02", "5.01")
    assert parse_reply(b"d\r\n", "D") == Reply("d")
    assert int_fields(parse_reply(b"h,1200,-1200\r\n", "H"), 2) == (1200, -1200)


def test_protocol_error_reply() -> None:
    with pytest.raises(RobotProtocolError, match="rejected the D command"):
        parse_reply(b"z,Protocol error\r\n", "D")


@pytest.mark.parametrize(
    "line",
    [b"\xffh,1,2\r\n", b"h,1\x07,2\r\n", b"e,1,2\r\n", b"\r\n", b"H,1,2\r\n", b"h1,2\r\n"],
)
def test_garbled_replies(line: bytes) -> None:
    with pytest.raises(GarbledReply):
        parse_reply(line, "H")


@pytest.mark.parametrize("line", [b"h,1\r\n", b"h,1,x\r\n", b"h,1_0,2\r\n", b"h, 1,2\r\n"])
def test_int_fields_reject_wrong_fields(line: bytes) -> None:
    with pytest.raises(GarbledReply, match="should carry 2 integers"):
        int_fields(parse_reply(line, "H"), 2)


@pytest.mark.parametrize("line", [b"d,1,2\r", b"D,1.5\r", b"\xc4,1\r", b"DD\r", b",1\r", b"D,\r"])
def test_malformed_requests(line: bytes) -> None:
    with pytest.raises(RobotProtocolError, match="malformed request"):
        parse_request(line)


def test_encode_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="upper-case"):
        encode_request("d", 1)
    with pytest.raises(TypeError):
        encode_request("D", True)
    with pytest.raises(ValueError, match="printable"):
        encode_reply("h", "a\r\n")


def test_errors_are_robot_errors() -> None:
    assert issubclass(GarbledReply, RobotError) and issubclass(RobotProtocolError, RobotError)
