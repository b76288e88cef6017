"""``bslam info LOG.mcap``: channels, counts, duration, session metadata, finished or not."""

from __future__ import annotations

import click


@click.command("info")
@click.argument("log", type=click.Path(dir_okay=False))
def info(log: str) -> None:
    """Summarise a log: channels, counts, duration, session metadata, finished or not.

    An unfinished log (the recording was interrupted) is summarised up to its last complete
    chunk, then the command exits 1 and suggests `bslam recover`.
    """
    import datetime
    import json

    from data_schemas.errors import BslamError, UnfinishedLogError
    from data_schemas.registry import SESSION_METADATA_NAME
    from data_schemas.session import session_from_metadata
    from recorder.logread import log_summary

    s = log_summary(log)

    def when(t_ns: int | None) -> str:
        if t_ns is None:
            return "-"
        return datetime.datetime.fromtimestamp(t_ns / 1e9, tz=datetime.UTC).isoformat()

    state = "finished (indexed)" if s.finished else "UNFINISHED (recording was interrupted)"
    click.echo(f"{s.name}: {state}")
    record = s.metadata.get(SESSION_METADATA_NAME)
    if record is None:
        click.echo("session: none (no 'bslam.session' metadata: not a bearing-slam recording?)")
    else:
        try:
            session = session_from_metadata(record)
        except BslamError as exc:
            click.echo(f"session: invalid ({exc})")
        else:
            doc = session.doc
            robot, camera = doc["robot"], doc["camera"]
            cal = session.calibration
            kind = "simulated" if session.simulated else "recorded"
            click.echo(
                f"session: {kind} with {robot['model']} on {robot['port']}, "
                f"software {doc['software_version']}, created {when(doc['created_unix_ns'])}"
            )
            click.echo(
                f"camera: {camera['source']}, {cal.model} {cal.width}x{cal.height}, "
                f"{camera.get('encoding', '?')}, {camera.get('frame_rate_hz', '?')} Hz"
            )
            catalog = ", ".join(f"{lm.name} ({lm.label})" for lm in session.landmarks)
            click.echo(
                f"landmarks: {catalog}; reference {session.reference[0]}, "
                f"{session.reference[1]}; vision error {doc['vision_error_deg']:g} deg"
            )
    others = sorted(set(s.metadata) - {SESSION_METADATA_NAME})
    for name in others:
        click.echo(f"metadata {name}: {json.dumps(s.metadata[name])}")
    click.echo(
        f"messages: {s.message_count} in {s.chunk_count} chunks; start {when(s.start_ns)}, "
        f"end {when(s.end_ns)}, duration {s.duration_s:.3f} s"
    )
    width = max([len("topic")] + [len(c.topic) for c in s.channels])
    swidth = max([len("schema")] + [len(c.schema) for c in s.channels])
    click.echo(f"  {'topic':<{width}}  {'schema':<{swidth}}  count")
    for c in s.channels:
        click.echo(f"  {c.topic:<{width}}  {c.schema:<{swidth}}  {c.count}")
    if not s.finished:
        raise UnfinishedLogError(
            f"{s.name} is unfinished: {s.message_count} messages are readable "
            f"({s.trailing_bytes} bytes of an incomplete chunk follow); "
            f"run `bslam recover {s.name} FIXED.mcap`"
        )
