"""Every default setting of the method and of imports, in one numpy-free module.

The command line (option defaults, so ``bslam --help`` loads no numpy), the Python API
(:class:`replay.records.MethodConfig`, :func:`replay.process.process_log`), the importers and the
experiments all take their defaults from here, so that one log gives one map whichever way it is
processed (``tests/replay/test_api_equals_cli.py``).
"""

from __future__ import annotations

#: Bound eps (degrees) on the bearing error of an imported log whose source does not give one:
#: the impartial PDF's angular width. UTIAS MRCLAM's camera, against its motion-capture truth:
#: median error 0.2-1.8 deg per landmark and robot (docs/RESULTS.md).
IMPORT_VISION_ERROR_DEG = 2.0
