"""Khepera (II) serial ASCII protocol: pure encode and parse functions.

A request is one upper-case command letter, then comma-separated integers, ended by CR::

    D,10,-10\\r        set wheel speeds
    H\\r               read position counters

A reply is the same letter in lower case, then comma-separated fields, ended by CR LF::

    d\\r\\n
    h,1200,-1200\\r\\n
    b,5.02,5.01\\r\\n  (fields need not be integers)

A robot that does not understand a request answers ``z,...`` (protocol error). The same shape
serves the e-puck ASCII protocol. These functions do no I/O; the driver
(:mod:`recorder.robot.khepera`) and the simulated robot (:mod:`recorder.sim.fake_khepera`) share
them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from recorder.robot.errors import GarbledReply, RobotProtocolError

#: End of a request line.
REQUEST_END = b"\r"
#: End of a reply line.
REPLY_END = b"\r\n"
#: First letter of a protocol-error reply.
ERROR_LETTER = "z"

_INT = re.compile(r"-?[0-9]+")


@dataclass(frozen=True)
class Request:
    """A decoded request: command letter (upper case) and integer arguments."""

    letter: str
    args: tuple[int, ...] = ()

    @property
    def text(self) -> str:
        """The request line without its CR, e.g. ``"D,10,-10"``."""
        return ",".join([self.letter, *(str(a) for a in self.args)])


@dataclass(frozen=True)
class Reply:
    """A decoded reply: letter (lower case) and its text fields."""

    letter: str
    fields: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        """The reply line without CR LF, e.g. ``"h,1200,-1200"``."""
        return ",".join([self.letter, *self.fields])


def _parse_int(text: str) -> int:
    if _INT.fullmatch(text) is None:
        raise ValueError(f"not an integer: {text!r}")
    return int(text)


def _check_letter(letter: str, *, upper: bool) -> None:
    ok = len(letter) == 1 and letter.isascii() and letter.isalpha()
    if not ok or letter.isupper() != upper:
        case = "upper" if upper else "lower"
        raise ValueError(f"command letter must be one {case}-case ASCII letter, got {letter!r}")


def encode_request(letter: str, *args: int) -> bytes:
    """Encode a request line, CR included.

    Parameters
    ----------
    letter : str
        One upper-case ASCII letter, e.g. ``"D"``.
    *args : int
        Integer arguments (pulses, speeds).

    Returns
    -------
    bytes
        e.g. ``b"D,10,-10\\r"``.
    """
    _check_letter(letter, upper=True)
    for a in args:
        if isinstance(a, bool) or not isinstance(a, int):
            raise TypeError(f"request arguments must be integers, got {a!r}")
    return Request(letter, tuple(args)).text.encode("ascii") + REQUEST_END


def _strip_line(line: bytes, end: bytes) -> bytes:
    if line.endswith(end):
        return line[: -len(end)]
    return line.rstrip(b"\r\n")


def _is_printable(text: str) -> bool:
    return all(" " <= ch <= "~" for ch in text)


def decode_line(line: bytes) -> str | None:
    """Reply bytes as text without CR LF, or None if they are not printable ASCII."""
    body = _strip_line(line, REPLY_END)
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError:
        return None
    return text if _is_printable(text) else None


def parse_reply(line: bytes, expected: str) -> Reply:
    """Decode a reply line (CR LF optional) to the request with letter ``expected``.

    Parameters
    ----------
    line : bytes
        Reply bytes as received.
    expected : str
        Letter of the request (either case).

    Raises
    ------
    RobotProtocolError
        The robot answered ``z,...``.
    GarbledReply
        Not printable ASCII, not ``letter[,field...]``, or the letter of another command.
    """
    text = decode_line(line)
    if text is None:
        raise GarbledReply(
            f"robot reply {line!r} is not printable ASCII; check the baud rate and cable"
        )
    letter, _, rest = text.partition(",")
    if letter == ERROR_LETTER:
        raise RobotProtocolError(
            f"robot rejected the {expected.upper()} command ({text!r}); "
            "check that the robot model and firmware match the configuration"
        )
    if letter != expected.lower():
        raise GarbledReply(
            f"robot reply {text!r} does not answer the {expected.upper()} command; "
            "check the baud rate and that no other program uses the port"
        )
    fields = tuple(rest.split(",")) if "," in text else ()
    return Reply(letter, fields)


def int_fields(reply: Reply, count: int) -> tuple[int, ...]:
    """The first ``count`` fields of ``reply`` as integers (GarbledReply if absent or not ints)."""
    try:
        if len(reply.fields) < count:
            raise ValueError
        return tuple(_parse_int(f) for f in reply.fields[:count])
    except ValueError:
        raise GarbledReply(
            f"robot reply {reply.text!r} should carry {count} integers; "
            "check the baud rate and the robot model"
        ) from None


def encode_reply(letter: str, *fields: str | int) -> bytes:
    """Encode a reply line, CR LF included (what a robot sends), e.g. ``b"h,1,2\\r\\n"``."""
    _check_letter(letter, upper=False)
    text = ",".join([letter, *(str(f) for f in fields)])
    if not _is_printable(text):
        raise ValueError(f"reply fields must be printable ASCII, got {text!r}")
    return text.encode("ascii") + REPLY_END


def parse_request(line: bytes) -> Request:
    """Decode a request line (CR or LF optional), as a robot does.

    Raises
    ------
    RobotProtocolError
        Not an upper-case letter followed by comma-separated integers.
    """
    body = line.rstrip(b"\r\n")
    try:
        text = body.decode("ascii")
        letter, *parts = text.split(",")
        _check_letter(letter, upper=True)
        args = tuple(_parse_int(p) for p in parts)
    except ValueError:  # UnicodeDecodeError is a ValueError
        raise RobotProtocolError(
            f"malformed request {body!r}: expected an upper-case letter and integers"
        ) from None
    return Request(letter, args)
