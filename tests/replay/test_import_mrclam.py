"""`bslam import mrclam`: a tiny MRCLAM-format dataset written here, imported and read back with
the mcap library; values checked by hand."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from importing import on, read_back

from replay.cli import cli

HEADER = "# a comment line, as in the dataset\n"
# subjects 1-2 are robots; 6, 7, 8 landmarks; barcode 99 is in no table
BARCODES = HEADER + "1 5\n2 14\n6 72\n7 27\n8 54\n"
LANDMARKS = HEADER + "6 2.0 0.0 0.001 0.001\n7 0.0 2.0 0.001 0.001\n8 -2.0 0.0 0.001 0.001\n"
# robot 1 at the origin, heading +x, turns in place at pi/2 rad/s from t = 1 s to t = 2 s
ODOMETRY = "0 0 0\n1 0 1.5707963267948966\n2 0 0\n3 0 0\n"
TRUTH = "0 0 0 0\n1 0 0 0\n2 0 0 1.5707963267948966\n3 0 0 1.5707963267948966\n"
# bearings as the truth gives them: L6 at 0, L7 at +pi/2 (t = 0.5); after the turn L6 at -pi/2,
# L8 at +pi/2 (t = 2.5); the other robot (barcode 14) and barcode 99 in between
MEASUREMENTS = (
    "0.5 72 2.0 0.0\n0.5 27 2.0 1.5707963\n1.5 14 1.0 0.3\n1.5 99 1.0 0.2\n"
    "2.5 72 2.0 -1.5707963\n2.5 54 2.0 1.5707963\n2.75 27 2.0 0.0001\n"
)


def _dataset(tmp_path: Path, **files: str) -> Path:
    folder = tmp_path / "MRCLAM_Dataset1"
    folder.mkdir()
    contents = {
        "Barcodes.dat": BARCODES,
        "Landmark_Groundtruth.dat": LANDMARKS,
        "Robot1_Odometry.dat": ODOMETRY,
        "Robot1_Measurement.dat": MEASUREMENTS,
        "Robot1_Groundtruth.dat": TRUTH,
    }
    contents.update({k.replace("_dat", ".dat"): v for k, v in files.items()})
    for name, text in contents.items():
        (folder / name).write_text(text)
    return folder


def _import(folder: Path, *extra: str) -> tuple[int, str]:
    out = folder.parent / "r1.mcap"
    result = CliRunner().invoke(
        cli, ["import", "mrclam", str(folder), "--robot", "1", "-o", str(out), *extra]
    )
    return result.exit_code, result.output


def test_landmark_bearings_odometry_and_truth(tmp_path: Path) -> None:
    folder = _dataset(tmp_path)
    code, output = _import(folder)
    assert code == 0, output
    assert "dropped 1 sightings of other robots" in output
    assert "dropped 1 sightings of barcodes missing from the barcode table" in output
    session, messages = read_back(tmp_path / "r1.mcap")
    assert [lm["name"] for lm in session["landmarks"]] == ["L6", "L7", "L8"]
    # L6 and L7 are seen twice each, L8 once: the two most seen are the reference pair
    assert session["reference"] == ["L6", "L7"]
    assert session["truth"]["landmarks"][2] == {"name": "L8", "x_m": -2.0, "y_m": 0.0}
    sets = on(messages, "/sensor/bearings")
    assert [(s["timestamp"]["sec"], s["timestamp"]["nsec"]) for s in sets] == [
        (0, 500_000_000), (2, 500_000_000), (2, 750_000_000)
    ]  # fmt: skip
    assert [[(b["landmark"], b["bearing_rad"]) for b in s["bearings"]] for s in sets] == [
        [("L6", 0.0), ("L7", 1.5707963)],
        [("L6", -1.5707963), ("L8", 1.5707963)],
        [("L7", 0.0001)],
    ]
    poses = [(p["x_m"], p["y_m"], p["theta_rad"]) for p in on(messages, "/robot/odometry_pose")]
    turned = (0, 0, math.pi / 2)
    for got, want in zip(poses, [(0, 0, 0), (0, 0, 0), turned, turned], strict=True):
        assert got == pytest.approx(want, abs=1e-15)
    truth = on(messages, "/truth/robot_pose")
    assert [(t["x"], t["y"], t["heading"]) for t in truth] == [
        (0, 0, 0), (0, 0, 0), (0, 0, 1.5707963267948966), (0, 0, 1.5707963267948966)
    ]  # fmt: skip
    files = {f["name"]: f for f in session["provenance"]["files"]}
    assert set(files) == {
        "Barcodes.dat", "Landmark_Groundtruth.dat", "Robot1_Odometry.dat",
        "Robot1_Measurement.dat", "Robot1_Groundtruth.dat",
    }  # fmt: skip
    for name, entry in files.items():
        assert entry["sha256"] == hashlib.sha256((folder / name).read_bytes()).hexdigest()
    assert session["provenance"]["options"]["robot"] == 1


def test_a_wrong_barcode_table_is_reported_and_corrected(tmp_path: Path) -> None:
    # the table swaps the barcodes of landmarks 6 and 8: their sightings point the wrong way
    swapped = BARCODES.replace("6 72", "6 54").replace("8 54", "8 72")
    folder = _dataset(tmp_path, Barcodes_dat=swapped)
    code, output = _import(folder)
    assert code == 0
    assert "check the barcode table: L6 (barcode 54)" in output
    assert "check the barcode table: L8 (barcode 72)" in output
    # barcode 54's sightings are where the truth puts L8, and 72's where it puts L6
    assert "it fits L8 (0.0 deg): try --barcode 8=54" in output
    assert "it fits L6 (0.0 deg): try --barcode 6=72" in output
    assert "L7" not in output.split("check the barcode table")[-1].split("\n")[0]
    code, output = _import(folder, "--barcode", "6=72", "--barcode", "8=54", "--force")
    assert code == 0 and "check the barcode table" not in output
    session, messages = read_back(tmp_path / "r1.mcap")
    first = on(messages, "/sensor/bearings")[0]["bearings"]
    assert first[0] == {"landmark": "L6", "bearing_rad": 0.0}
    assert session["provenance"]["options"]["barcodes"] == {"6": 72, "8": 54}


def test_times_printed_with_too_few_digits_get_their_grid_back(tmp_path: Path) -> None:
    # rows every 0.02 s from 999.92 s, printed with 5 significant digits (true 1000.02 prints
    # as 1000, true 1000.06 as 1000.1)
    printed = ["999.92", "999.94", "999.96", "999.98", "1000", "1000", "1000", "1000.1", "1000.1"]
    rows = "".join(f"{t} 0.1 0\n" for t in printed)
    folder = _dataset(tmp_path, Robot1_Odometry_dat=rows)
    code, output = _import(folder)
    assert code == 0, output
    _, messages = read_back(tmp_path / "r1.mcap")
    poses = on(messages, "/robot/odometry_pose")
    t_ns = [p["timestamp"]["sec"] * 10**9 + p["timestamp"]["nsec"] for p in poses]
    assert t_ns == [999_920_000_000 + 20_000_000 * i for i in range(9)]
    assert [p["x_m"] for p in poses] == pytest.approx([0.002 * i for i in range(9)], abs=1e-12)


@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({"Robot1_Odometry_dat": "0 0 0\n1 0 0\n1 0 0\n5 0 0\n"},
         "Robot1_Odometry.dat:3: time repeats the previous row's"),
        ({"Robot1_Measurement_dat": "0.5 72 2.0 x\n"},
         "Robot1_Measurement.dat:1: bearing_rad is 'x', not a number"),
        ({"Robot1_Groundtruth_dat": "0 0 0\n"}, "Robot1_Groundtruth.dat:1: 3 fields, expected 4"),
        ({"Barcodes_dat": "1 5\n2 5\n"}, "Barcodes.dat:2: barcode 5 is given to subjects 1 and 2"),
    ],
)  # fmt: skip
def test_bad_files_are_one_line_with_the_line_number(
    tmp_path: Path, files: dict[str, str], message: str
) -> None:
    code, output = _import(_dataset(tmp_path, **files))
    assert code == 1
    assert message in output and output.startswith("Error: ") and output.count("\n") == 1
    assert not (tmp_path / "r1.mcap").exists()


def test_missing_folder_or_file(tmp_path: Path) -> None:
    code, output = _import(tmp_path / "nowhere")
    assert (
        code == 1
        and output == f"Error: MRCLAM dataset folder {tmp_path / 'nowhere'} does not exist\n"
    )
    folder = _dataset(tmp_path)
    (folder / "Robot1_Groundtruth.dat").unlink()
    code, output = _import(folder)
    assert (
        code == 1
        and "robot truth file" in output
        and "Robot1_Groundtruth.dat does not exist" in output
    )
