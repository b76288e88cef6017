"""What every log reader shares: one message of a log, and the lines that refuse a damaged one.

:class:`LogMessage` is what :class:`data_schemas.mcap.open.MessageLog` readers yield;
:func:`unfinished_line` and :func:`corrupt_log_line` are the one wording of an unfinished and of
a corrupt log (``bslam recover`` rewrites what is left); :data:`IDLE_TIMEOUT_S` is how long a
log being followed may stay still (a light module: the CLI's ``--help`` reads it).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import IO, Any

from data_schemas.codec import decode
from data_schemas.errors import (
    recover_hint,
)
from data_schemas.mcap.scan import Damage
from data_schemas.shape import check_shape

Source = str | os.PathLike[str] | IO[bytes]

#: Default seconds without growth before following a log stops (the recorder closes a chunk at
#: least every 0.5 s while it writes, and it writes while the robot moves or is polled).
IDLE_TIMEOUT_S = 10.0
#: Damage that an interrupted recording leaves (the file just ends): "unfinished", not corrupt.
CUT_END = frozenset({"cut chunk", "file end"})


@dataclass(frozen=True)
class LogMessage:
    """One message of a log, not yet decoded.

    Attributes
    ----------
    topic, schema : str
        Channel topic and schema name.
    log_time_ns, publish_time_ns : int
        When the recorder wrote it, and the message's own ``timestamp`` (ns since the epoch).
    sequence : int
        Per-channel counter from 1.
    data : bytes
        The JSON message.
    """

    topic: str
    schema: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes = field(repr=False)

    def decode(self) -> dict[str, Any]:
        """The message as a dict: JSON decoded, required fields and their types checked.

        Raises
        ------
        SchemaError
            One line naming the topic, the log time and the field.
        """
        msg = decode(self.topic, self.data)
        check_shape(self.schema, msg, topic=self.topic, log_time_ns=self.log_time_ns)
        return msg


def corruption(damage: list[Damage]) -> list[Damage]:
    """The damage that is more than a cut-off end (what makes a log corrupt, not unfinished)."""
    return [d for d in damage if d.what not in CUT_END]


def unfinished_line(
    name: str, count: int, trailing_bytes: int | None = None, path: str | None = None
) -> str:
    """One line on an unfinished log: how many messages are readable, and what to do.

    ``path`` (default ``name``) is the file named in the ``bslam recover`` advice.
    """
    rest = (
        "" if trailing_bytes is None else f" ({trailing_bytes} bytes of an incomplete chunk follow)"
    )
    return (
        f"{name} is unfinished (the recording was interrupted): {count} messages are "
        f"readable{rest}; {recover_hint(path or name)}"
    )


def corrupt_log_line(name: str, damage: list[Damage], advice: str) -> str:
    """One line naming the first damage of a corrupt log, how much more, and what to do."""
    more = f" (and {len(damage) - 1} more)" if len(damage) > 1 else ""
    return f"{name} is corrupt: {damage[0].describe()}{more}; {advice}"
