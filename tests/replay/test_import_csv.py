"""`bslam import csv`: bearings and odometry CSV files and a catalog into a log, read back with
the mcap library and checked against hand-computed values."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from importing import on, read_back

from data_schemas.mcap.processable import ProcessableLog
from replay.cli import cli
from tests.mcap_reader import LogReader


def _files(tmp_path: Path, bearings: str, odometry: str, catalog: object) -> list[str]:
    (tmp_path / "b.csv").write_text(bearings)
    (tmp_path / "o.csv").write_text(odometry)
    (tmp_path / "c.json").write_text(json.dumps(catalog))
    return [
        "import", "csv",
        "--bearings", str(tmp_path / "b.csv"),
        "--odometry", str(tmp_path / "o.csv"),
        "--landmarks", str(tmp_path / "c.json"),
        "--out", str(tmp_path / "log.mcap"),
    ]  # fmt: skip


BEARINGS = (
    "t_s,landmark,bearing_rad,std_rad\n"
    "0.5,A,0.123456789012345,\n"
    "0.5,B,-3.0,0.01\n"
    "1.000000001,C,3.5,\n"  # wrapped: 3.5 - 2 pi
)
CATALOG = {"landmarks": [{"name": "A"}, {"name": "B"}, {"name": "C"}]}


def test_velocities_are_integrated_and_bearings_read_back_exactly(tmp_path: Path) -> None:
    # 1 s straight at 1 m/s, then a quarter turn in place, then 1 s straight, then a quarter
    # circle of radius 2/pi (1 m/s, pi/2 rad/s); poses by hand
    odometry = (
        "t_s,v_mps,omega_radps\n"
        "0,1,0\n1,0,1.5707963267948966\n2,1,0\n3,1,1.5707963267948966\n4,0,0\n"
    )
    result = CliRunner().invoke(cli, _files(tmp_path, BEARINGS, odometry, CATALOG))
    assert result.exit_code == 0, result.output
    session, messages = read_back(tmp_path / "log.mcap")
    poses = [(p["x_m"], p["y_m"], p["theta_rad"]) for p in on(messages, "/robot/odometry_pose")]
    r = 2 / math.pi
    expected = [
        (0, 0, 0),
        (1, 0, 0),
        (1, 0, math.pi / 2),
        (1, 1, math.pi / 2),
        (1 - r, 1 + r, -math.pi),
    ]
    assert len(poses) == len(expected)
    for got, want in zip(poses, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-12)
    sets = on(messages, "/sensor/bearings")
    assert [s["timestamp"] for s in sets] == [
        {"sec": 0, "nsec": 500_000_000},
        {"sec": 1, "nsec": 1},
    ]
    assert sets[0]["bearings"] == [
        {"landmark": "A", "bearing_rad": 0.123456789012345},
        {"landmark": "B", "bearing_rad": -3.0, "std_rad": 0.01},
    ]
    assert sets[1]["bearings"] == [{"landmark": "C", "bearing_rad": 3.5 - 2 * math.pi}]
    # messages in time order; log time = sensor time
    times = [(lt, pt) for _, lt, pt, _ in messages]
    assert [lt for lt, _ in times] == sorted(lt for lt, _ in times)
    assert all(lt == pt for lt, pt in times)
    assert session["reference"] == ["A", "B"]
    assert "camera" not in session and "robot" not in session


def test_provenance_hashes_are_the_files_sha256(tmp_path: Path) -> None:
    odometry = "t_s,x_m,y_m,theta_rad\n0,0,0,0\n2,1.25,-0.5,0.75\n"
    args = _files(tmp_path, BEARINGS, odometry, CATALOG)
    assert CliRunner().invoke(cli, args).exit_code == 0
    session, messages = read_back(tmp_path / "log.mcap")
    prov = session["provenance"]
    assert prov["kind"] == "csv" and prov["importer_version"] >= 1
    for entry, name in zip(prov["files"], ("b.csv", "o.csv", "c.json"), strict=True):
        data = (tmp_path / name).read_bytes()
        assert entry["name"] == name
        assert entry["sha256"] == hashlib.sha256(data).hexdigest()
        assert entry["bytes"] == len(data)
    poses = on(messages, "/robot/odometry_pose")
    assert poses[1] == {
        "timestamp": {"sec": 2, "nsec": 0}, "x_m": 1.25, "y_m": -0.5, "theta_rad": 0.75
    }  # fmt: skip


def test_session_without_camera_opens_with_names_as_classes(tmp_path: Path) -> None:
    catalog = {
        "landmarks": [{"name": "A", "x_m": 0, "y_m": 0}, {"name": "B", "x_m": 2, "y_m": 0},
                      {"name": "C", "x_m": 1, "y_m": 1.5}],
        "reference": ["B", "C"],
        "vision_error_deg": 1.5,
    }  # fmt: skip
    args = _files(tmp_path, BEARINGS, "t_s,x_m,y_m,theta_rad\n0,0,0,0\n", catalog)
    assert CliRunner().invoke(cli, args).exit_code == 0
    with LogReader(tmp_path / "log.mcap") as log:
        session = log.session()
    assert session.calibration is None
    assert [lm.label for lm in session.landmarks] == ["A", "B", "C"]
    assert session.reference == ("B", "C")
    assert session.vision_error_rad == pytest.approx(math.radians(1.5))
    assert session.truth_landmarks_m() == {"A": (0, 0), "B": (2, 0), "C": (1, 1.5)}
    info = CliRunner().invoke(cli, ["info", str(tmp_path / "log.mcap")])
    assert "camera: none" in info.output and "imported by the csv importer" in info.output
    # a log without a camera opens for processing (its bearings are not in frames)
    with ProcessableLog(tmp_path / "log.mcap") as log:
        assert set(log.topics) == {"/sensor/bearings", "/robot/odometry_pose"}


@pytest.mark.parametrize(
    ("bearings", "odometry", "catalog", "message"),
    [
        (BEARINGS.replace("-3.0", "abc"), None, None,
         "b.csv:3: bearing_rad is 'abc', not a number"),
        (BEARINGS.replace("1.000000001,C", "1.000000001,Z"), None, None,
         "b.csv:4: landmark 'Z' is not in the catalog"),
        (BEARINGS.replace("1.000000001", "0.25"), None, None, "b.csv:4: times must not decrease"),
        ("t_s,landmark,bearing\n", None, None, "unknown column 'bearing'"),
        (BEARINGS + "2,A\n", None, None, "b.csv:5: 2 fields, expected 4"),
        (None, "t_s,v_mps,omega_radps\n0,1,0\n0,1,0\n", None, "o.csv:3: times must increase"),
        (None, "t_s,x_m,y_m\n0,0,0\n", None, "missing column 'theta_rad'"),
        (None, "t_s,x_m,y_m,theta_rad\n-1,0,0,0\n", None, "o.csv:2: t_s is '-1'"),
        (None, None, {"landmarks": [{"name": "A"}]}, "at least two landmarks"),
        (None, None, {"landmarks": [{"name": "A"}, {"name": "B"}], "reference": ["A", "Q"]},
         "reference must be two different landmark names"),
    ],
)  # fmt: skip
def test_bad_input_is_one_line_and_exit_1(
    tmp_path: Path, bearings: str | None, odometry: str | None, catalog: object, message: str
) -> None:
    args = _files(
        tmp_path,
        BEARINGS if bearings is None else bearings,
        "t_s,x_m,y_m,theta_rad\n0,0,0,0\n" if odometry is None else odometry,
        CATALOG if catalog is None else catalog,
    )
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    assert message in result.output
    assert result.output.count("\n") == 1 and result.output.startswith("Error: ")
    assert not (tmp_path / "log.mcap").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.csv", "c.json", "o.csv"]


def test_missing_file_and_existing_output(tmp_path: Path) -> None:
    args = _files(tmp_path, BEARINGS, "t_s,x_m,y_m,theta_rad\n0,0,0,0\n", CATALOG)
    (tmp_path / "o.csv").unlink()
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1
    assert result.output == f"Error: odometry file {tmp_path / 'o.csv'} does not exist\n"
    (tmp_path / "o.csv").write_text("t_s,x_m,y_m,theta_rad\n0,0,0,0\n")
    (tmp_path / "log.mcap").write_bytes(b"keep")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and "exists: pass --force" in result.output
    assert (tmp_path / "log.mcap").read_bytes() == b"keep"
    assert CliRunner().invoke(cli, [*args, "--force"]).exit_code == 0
    assert read_back(tmp_path / "log.mcap")[0]["landmarks"][0] == {"name": "A"}
