"""``bslam demo``: the paper's arena simulated, mapped and ready to open in Rerun."""

from __future__ import annotations

from pathlib import Path

import click

from replay.cli.options import SEED, estimator_option


@click.command("demo")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("bslam-demo"),
    show_default=True,
    help="Folder for the results.",
)
@click.option(
    "--seed",
    type=SEED,
    default=7,
    show_default=True,
    help="Seed of the simulated trajectory and of the estimator.",
)
@click.option("--omni", is_flag=True, help="Use the omnidirectional (donut) camera model.")
@click.option("--force", is_flag=True, help="Replace the results of an earlier demo in --out.")
@estimator_option
def demo(out_dir: Path, seed: int, omni: bool, force: bool, estimator: str) -> None:
    """Simulate the paper's arena (10 movements), build the map, write demo.rrd.

    Writes the simulated log, the derived log, the summary JSON and a Rerun recording of every
    stage into --out, then says how to open them.
    """
    from replay.extras import require_viewer

    require_viewer("bslam demo")
    from data_schemas.outputs import OutputGuard
    from recorder.sim.scenario import builtin_scenario
    from recorder.sim.simulate import simulate_to_file
    from replay.cli.process import show_skips
    from replay.cli.recording import run_recording, viewing_hints
    from replay.process import result_line
    from replay.records import MethodConfig
    from replay.rerun_out import save_rrd
    from replay.sinks.progress import ProgressSink

    log = out_dir / "demo.mcap"
    rrd, derived, summary = (
        out_dir / "demo.rrd",
        out_dir / "demo.derived.mcap",
        out_dir / "demo.summary.json",
    )
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise click.ClickException(f"cannot create folder {out_dir}: {exc.strerror}") from None
    guard = OutputGuard(force=force)
    for path in (log, rrd, derived, summary):  # all refused before anything is written
        guard.claim(path, what="demo output")
    scenario = "paper_omni" if omni else "paper"
    click.echo(f"simulating the paper's arena ({scenario}, seed {seed}) ...")
    sim = builtin_scenario(scenario).with_seed(seed)
    run_recording(
        log,
        lambda path, progress: simulate_to_file(sim, path, source=scenario, progress=progress),
        total=sim.trajectory.n_moves,
        force=force,
        staged=True,
    )
    with show_skips():
        doc = save_rrd(
            log,
            MethodConfig(seed=seed, estimator=estimator),
            rrd,
            out=derived,
            summary=summary,
            force=force,
            extra_sinks=(ProgressSink(total=sim.trajectory.n_moves),),
        )
    click.echo(f"map: {result_line(doc)}")
    l1, l2 = doc.reference
    click.echo(f"landmarks in FL, the map frame: {l1} at (0, 0), {l2} at (1, 0), unit |{l1} {l2}|")
    document = doc.to_json()
    for name, est in document["landmarks"].items():
        x, y = est["mean"]
        err = document.get("error_m", {}).get(name)
        more = "" if err is None else f"  (error {100 * err:.1f} cm)"
        click.echo(f"  {name} at ({x:+.3f}, {y:+.3f}) in FL{more}")
    click.echo("results:")
    click.echo(f"  simulated log  {log}")
    click.echo(f"  derived log    {derived}")
    click.echo(f"  summary        {summary}")
    click.echo(f"  Rerun          {rrd}")
    for line in viewing_hints(rrd):
        click.echo(line)
