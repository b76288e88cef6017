"""``bslam import``: another format in, an ordinary bearing-slam log out (one subcommand each).

Each subcommand makes one importer (:mod:`replay.importers`) and hands it to
:func:`replay.importers.write.import_log`; it prints the importer's notes and what was written.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from replay.cli.options import FiniteFloat
from replay.defaults import IMPORT_VISION_ERROR_DEG

if TYPE_CHECKING:
    from replay.importers.source import Importer


def _reference(
    ctx: click.Context, param: click.Parameter, value: str | None
) -> tuple[str, str] | None:
    if value is None:
        return None
    names = [n.strip() for n in value.split(",")]
    if len(names) != 2 or not all(names) or names[0] == names[1]:
        raise click.BadParameter(f"expected two different landmark names A,B, got {value!r}")
    return names[0], names[1]


out_option = click.option(
    "--out",
    "-o",
    required=True,
    type=click.Path(dir_okay=False),
    help="The log to write (MCAP).",
)
force_option = click.option("--force", is_flag=True, help="Replace an existing --out.")
reference_option = click.option(
    "--reference",
    callback=_reference,
    metavar="L1,L2",
    help="The reference pair: the map's frame puts L1 at (0, 0) and L2 at (1, 0).",
)


def _run(importer: Importer, out: str, force: bool) -> None:
    """Import with a progress bar on stderr; print the notes and the counts."""
    from tqdm import tqdm

    from replay.importers.write import import_log

    with tqdm(unit="msg", file=sys.stderr, desc="importing", delay=0.5, disable=None) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        result = import_log(importer, out, force=force, progress=progress)
    for note in result.notes:
        click.echo(f"note: {note}", err=True)
    counts = ", ".join(f"{n} on {topic}" for topic, n in sorted(result.counts.items()))
    click.echo(f"wrote {result.path}: {counts}")


@click.group("import")
def import_group() -> None:
    """Write a bearing-slam log from another format: then `bslam process` it as any log.

    The log's session records where it came from (importer, version, every file's SHA-256).
    Landmarks are known by name; bearings go on /sensor/bearings, odometry on
    /robot/odometry_pose. Truth the source has (surveyed or motion-capture positions) is kept
    for evaluation only.
    """


@import_group.command("csv")
@click.option(
    "--bearings",
    required=True,
    type=click.Path(dir_okay=False),
    help="CSV: t_s,landmark,bearing_rad[,std_rad] (rad, CCW from the robot's heading).",
)
@click.option(
    "--odometry",
    required=True,
    type=click.Path(dir_okay=False),
    help="CSV of poses t_s,x_m,y_m,theta_rad or of velocities t_s,v_mps,omega_radps.",
)
@click.option(
    "--landmarks",
    required=True,
    type=click.Path(dir_okay=False),
    help='JSON: {"landmarks": [{"name": "A"}, ...], "reference": [...], "vision_error_deg": ...}.',
)
@out_option
@reference_option
@click.option(
    "--vision-error-deg",
    type=FiniteFloat(0.0, 90.0, min_open=True, max_open=True),
    default=None,
    help=f"Bound on the bearing error, degrees [default: the catalog's, else "
    f"{IMPORT_VISION_ERROR_DEG:g}].",
)
@force_option
def import_csv(
    bearings: str,
    odometry: str,
    landmarks: str,
    out: str,
    reference: tuple[str, str] | None,
    vision_error_deg: float | None,
    force: bool,
) -> None:
    """Bearings and odometry from CSV files, landmarks from a JSON catalog.

    Rows with the same t_s in the bearings file make one measurement. Velocities are
    integrated into poses (an arc per row, from that row's time to the next). See the README,
    "Your own robot's data", for the columns.
    """
    from replay.importers.csv_files import CsvImporter

    importer = CsvImporter(
        Path(bearings), Path(odometry), Path(landmarks), reference, vision_error_deg
    )
    _run(importer, out, force)


def _barcodes(
    ctx: click.Context, param: click.Parameter, values: tuple[str, ...]
) -> dict[int, int]:
    out: dict[int, int] = {}
    for value in values:
        subject, sep, barcode = value.partition("=")
        if not sep or not subject.strip().isdigit() or not barcode.strip().isdigit():
            raise click.BadParameter(f"expected SUBJECT=BARCODE (two integers), got {value!r}")
        out[int(subject)] = int(barcode)
    return out


@import_group.command("mrclam")
@click.argument("dataset_dir", type=click.Path(file_okay=False))
@click.option(
    "--robot", required=True, type=click.IntRange(1, 5), help="Which robot's data to import."
)
@out_option
@reference_option
@click.option(
    "--vision-error-deg",
    type=FiniteFloat(0.0, 90.0, min_open=True, max_open=True),
    default=IMPORT_VISION_ERROR_DEG,
    show_default=True,
    help="Bound on the bearing error, degrees.",
)
@click.option(
    "--barcode",
    "barcodes",
    multiple=True,
    callback=_barcodes,
    metavar="SUBJECT=BARCODE",
    help="Correct Barcodes.dat: this subject wears this barcode (repeatable).",
)
@force_option
def import_mrclam(
    dataset_dir: str,
    robot: int,
    out: str,
    reference: tuple[str, str] | None,
    vision_error_deg: float,
    barcodes: dict[int, int],
    force: bool,
) -> None:
    """One robot of a UTIAS MRCLAM dataset folder (RobotN_Odometry.dat, RobotN_Measurement.dat,
    Barcodes.dat, Landmark_Groundtruth.dat, RobotN_Groundtruth.dat).

    Bearings only (ranges ignored); sightings of the other robots are dropped. Motion-capture
    truth is kept for evaluation only. The barcode table is checked against the truth and
    suspect entries are reported. Reference pair by default: the two landmarks the robot sees
    most.
    """
    from replay.importers.mrclam import MrclamImporter

    importer = MrclamImporter(Path(dataset_dir), robot, reference, vision_error_deg, barcodes)
    _run(importer, out, force)


@import_group.command("rosbag")
@click.argument("bag", type=click.Path())
@click.option(
    "--landmarks",
    required=True,
    type=click.Path(dir_okay=False),
    help="Landmark file, as for `bslam record`: colours or bands, reference pair, eps.",
)
@out_option
@click.option("--image-topic", help="sensor_msgs/Image or CompressedImage [default: the only one].")
@click.option("--camera-info-topic", help="sensor_msgs/CameraInfo [default: the only one].")
@click.option("--odometry-topic", help="nav_msgs/Odometry [default: the only one].")
@click.option(
    "--calibration",
    type=click.Path(dir_okay=False),
    help="Camera calibration file instead of the bag's CameraInfo (bslam.Calibration JSON, "
    "ROS camera_info YAML or OpenCV FileStorage).",
)
@force_option
def import_rosbag(
    bag: str,
    landmarks: str,
    out: str,
    image_topic: str | None,
    camera_info_topic: str | None,
    odometry_topic: str | None,
    calibration: str | None,
    force: bool,
) -> None:
    """A ROS 2 bag folder (MCAP or .db3 storage; no ROS install needed): frames, the camera's
    calibration and wheel odometry.

    Frames are stored lossless (PNG); odometry becomes /robot/odometry_pose (x, y, yaw). Needs
    the 'ros' extra (rosbags).
    """
    from replay.importers.rosbag import RosbagImporter

    importer = RosbagImporter(
        Path(bag),
        Path(landmarks),
        image_topic,
        camera_info_topic,
        odometry_topic,
        None if calibration is None else Path(calibration),
    )
    _run(importer, out, force)


@import_group.command("images")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option(
    "--timestamps",
    required=True,
    type=click.Path(dir_okay=False),
    help="CSV: file,t_s (an image of FOLDER and its capture time, seconds).",
)
@click.option(
    "--calibration",
    required=True,
    type=click.Path(dir_okay=False),
    help="Camera calibration (bslam.Calibration JSON, ROS camera_info YAML or OpenCV FileStorage).",
)
@click.option(
    "--landmarks",
    required=True,
    type=click.Path(dir_okay=False),
    help="Landmark file, as for `bslam record`: colours or bands, reference pair, eps.",
)
@click.option(
    "--odometry",
    type=click.Path(dir_okay=False),
    help="Odometry CSV, as for `bslam import csv` (poses or velocities) [default: none].",
)
@out_option
@force_option
def import_images(
    folder: str,
    timestamps: str,
    calibration: str,
    landmarks: str,
    odometry: str | None,
    out: str,
    force: bool,
) -> None:
    """A folder of images with a timestamps file, and optionally an odometry CSV.

    Frames are stored lossless (PNG); greyscale images as three equal channels.
    """
    from replay.importers.images import ImageFolderImporter

    importer = ImageFolderImporter(
        Path(folder),
        Path(timestamps),
        Path(calibration),
        Path(landmarks),
        None if odometry is None else Path(odometry),
    )
    _run(importer, out, force)
