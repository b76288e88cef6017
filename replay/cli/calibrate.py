"""``bslam calibrate colors``: prints what :func:`replay.colors.calibrate_colors` learned."""

from __future__ import annotations

import click


@click.group("calibrate")
def calibrate() -> None:
    """Calibrate the camera's view of the landmarks from marked frames."""


@calibrate.command("colors")
@click.argument("frames", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "--marks",
    required=True,
    type=click.Path(dir_okay=False),
    help='JSON: {"marks": [{"frame": F, "landmark": L, "points": [[x, y], ...]} or '
    '{..., "columns": [x0, x1]}]}; mark every landmark that shows in a marked frame.',
)
@click.option(
    "--catalog",
    required=True,
    type=click.Path(dir_okay=False),
    help="The landmark file to start from (as for bslam record).",
)
@click.option(
    "--out",
    "-o",
    required=True,
    type=click.Path(dir_okay=False),
    help="The landmark file to write, with the learned HSV boxes.",
)
@click.option("--force", is_flag=True, help="Replace an existing --out.")
def colors(frames: tuple[str, ...], marks: str, catalog: str, out: str, force: bool) -> None:
    """Learn each landmark colour's HSV box from FRAMES where the landmarks are marked.

    Each colour's box holds its marked pixels (with room for dimmer light) and keeps out the
    rest of the marked frames (floor, walls, posters), and is written for every landmark and
    band of that colour.
    """
    from replay.colors import calibrate_colors

    result = calibrate_colors(frames, marks, catalog, out, force=force)
    for lb in result.learned:
        box = lb.box
        click.echo(
            f"{lb.color}: H {box.lo[0]}..{box.hi[0]}, S >= {box.lo[1]}, V >= {box.lo[2]} "
            f"(from {lb.n_positives} pixels: holds {100 * lb.positive_share:.1f} % of them and "
            f"{100 * lb.negative_share:.3f} % of the rest)"
        )
    if result.unmarked:
        click.echo(f"not marked (boxes kept): {', '.join(result.unmarked)}")
    click.echo(f"wrote {out}")
