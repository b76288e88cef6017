"""What the shape check on read costs next to decoding alone (``pytest tests/bench -s``).

Every message a log yields is decoded (``json.loads``) and then checked against its schema's
required fields and JSON types (:mod:`data_schemas.shape`). Both are timed on the same messages,
alternated round by round, and compared by their medians; full JSON Schema validation is timed
too, as the thing the cheap check replaces. Messages: a PNG frame (the bulk of a log) and a
movement (the smallest).
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Callable

import numpy as np
import pytest

from data_schemas.codec import decode, validate
from data_schemas.shape import check_shape

MOVEMENT = {
    "timestamp": {"sec": 1_700_000_000, "nsec": 5},
    "index": 3,
    "phase": "end",
    "keyframe_timestamp": {"sec": 1_700_000_000, "nsec": 5},
    "turn_rad": 0.4,
    "distance_m": 0.2,
}


def _frame() -> dict[str, object]:
    import base64

    import cv2

    image = np.random.default_rng(0).integers(0, 256, (176, 255, 3), np.uint8)
    ok, png = cv2.imencode(".png", image)
    assert ok
    return {
        "timestamp": {"sec": 1_700_000_000, "nsec": 5},
        "frame_id": "panorama",
        "format": "png",
        "data": base64.b64encode(png.tobytes()).decode(),
    }


def _mean_us(fn: Callable[[], object], n: int) -> float:
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return 1e6 * (time.perf_counter() - start) / n


@pytest.mark.parametrize(
    ("topic", "schema", "make"),
    [
        ("/robot/movement", "bslam.Movement", lambda: MOVEMENT),
        ("/camera/panorama", "foxglove.CompressedImage", _frame),
    ],
)
def test_shape_check_costs_little_next_to_decode(
    topic: str, schema: str, make: Callable[[], dict[str, object]]
) -> None:
    data = json.dumps(make()).encode()
    msg = decode(topic, data)

    def decode_only() -> object:
        return decode(topic, data)

    def decode_and_check() -> object:
        m = decode(topic, data)
        check_shape(schema, m, topic=topic, log_time_ns=0)
        return m

    def decode_and_validate() -> object:
        m = decode(topic, data)
        validate(schema, m, what=topic)
        return m

    check_shape(schema, msg, topic=topic, log_time_ns=0)  # compile once
    validate(schema, msg, what=topic)
    n = 200 if topic == "/camera/panorama" else 5000
    rounds: dict[str, list[float]] = {"decode": [], "decode+check": [], "decode+validate": []}
    for _ in range(15):  # alternated: the machine's load hits all three alike
        rounds["decode"].append(_mean_us(decode_only, n))
        rounds["decode+check"].append(_mean_us(decode_and_check, n))
        rounds["decode+validate"].append(_mean_us(decode_and_validate, n))
    med = {k: statistics.median(v) for k, v in rounds.items()}
    print(
        f"\n{topic}: decode {med['decode']:.2f} us, decode+check {med['decode+check']:.2f} us "
        f"(x{med['decode+check'] / med['decode']:.2f}), decode+validate "
        f"{med['decode+validate']:.2f} us (x{med['decode+validate'] / med['decode']:.2f})"
    )
    assert med["decode+check"] < med["decode+validate"]
