"""Optional dependencies: import them, or say which extra of bearing-slam installs them."""

from __future__ import annotations

import importlib
from types import ModuleType

from data_schemas.errors import BslamError


class MissingExtraError(BslamError):
    """An optional dependency is not installed (names the extra that installs it)."""


def require(module: str, *, extra: str, feature: str) -> ModuleType:
    """Import ``module`` or raise MissingExtraError naming ``extra``.

    Parameters
    ----------
    module : str
        Module to import, e.g. ``"matplotlib"``.
    extra : str
        The optional-dependency group of ``pyproject.toml`` that installs it.
    feature : str
        What needs it, for the message (e.g. ``"bslam experiment"``).
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{feature} needs {module.split('.')[0]}, which is not installed; install the "
            f"{extra!r} extra: pip install 'bearing-slam[{extra}]'"
        ) from None


def require_viewer(feature: str) -> None:
    """Fail early, with one line, if Rerun (the ``viewer`` extra) is not installed.

    Rerun 0.41 needs numpy >= 2; beside ROS 2 Jazzy (numpy 1.26) bearing-slam installs without
    it, and only the commands that draw into Rerun need it.
    """
    require("rerun", extra="viewer", feature=feature)
