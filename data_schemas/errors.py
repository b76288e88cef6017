"""The project's exception hierarchy.

Every error a user can cause (a wrong file, a missing port, a malformed scenario) is a subclass
of :class:`BslamError`. The CLI turns any ``BslamError`` into one line on stderr and exit code 1;
anything else is a bug and keeps its traceback. Packages add specific subclasses next to the code
that raises them, always deriving from one of the classes here.
"""

from __future__ import annotations

import os
import shlex


def recover_hint(log: str | os.PathLike[str]) -> str:
    """``run `bslam recover LOG FIXED.mcap``` with LOG quoted for a shell (one definition)."""
    return f"run `{shlex.join(['bslam', 'recover', os.fspath(log), 'FIXED.mcap'])}`"


class BslamError(Exception):
    """Root of every error bearing-slam reports to a user (message = one clear line)."""


class SchemaError(BslamError):
    """A message or document does not match its JSON Schema (names the topic and the field)."""


class ScenarioError(BslamError):
    """A simulation scenario file is missing, malformed or impossible (names the key)."""


class CalibrationError(BslamError):
    """A camera calibration is invalid or disagrees with the images."""


class LogError(BslamError):
    """An MCAP log cannot be read or written as asked."""


class NotMcapError(LogError):
    """The file is not an MCAP file."""


class UnfinishedLogError(LogError):
    """The MCAP file was not finished (no summary/footer); ``bslam recover`` can rewrite it."""


class CorruptLogError(LogError):
    """A log's bytes are damaged (a chunk fails its CRC, an index disagrees, records unreadable)."""


class MissingMetadataError(LogError):
    """The log lacks the session metadata (or a required part of it, such as calibration)."""


class UnknownSchemaError(LogError):
    """A channel carries a schema this version does not know."""


class DiskFullError(LogError):
    """The disk (or the file size limit) is full; the log is readable up to the last chunk."""


class OutputError(BslamError):
    """An output path may not be written: it is an input, exists, or cannot be created."""


class DeviceError(BslamError):
    """A hardware device (serial robot, camera) failed."""


class RobotError(DeviceError):
    """The serial robot failed; subclasses say how."""


class CameraError(DeviceError):
    """The camera could not be opened or stopped delivering frames."""


class ImageError(BslamError):
    """An image is unusable: wrong shape or dtype, lossy encoding, size not matching calibration."""


class EstimationError(BslamError):
    """Inputs to the estimator are invalid (unknown landmark, wrong shapes, bad parameters)."""
