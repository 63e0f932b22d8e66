"""``rerun-importer-workbench``: rerun's external data loader for flight logs, so ``rerun FLIGHT.tlog`` just works.

Rerun's viewer (and ``rr.log_file_from_path``) runs every executable on ``PATH`` whose name starts with
``rerun-importer-`` (rerun 0.41; before it ``rerun-loader-``, still accepted with a deprecation warning: the package
installs both names) on a file it is asked to open, passing the path and its settings; a loader either streams a
recording to stdout (``rr.stdout()``) or exits with code 66 (``rr.EXTERNAL_DATA_LOADER_INCOMPATIBLE_EXIT_CODE``)
to say the file is not for it. This one handles the logs the workbench reads by their first bytes — every
format declared in :mod:`adapters.formats` whose ``rerun_importer`` is true: MAVLink ``.tlog``, PX4 ULog, DataFlash
``.bin`` — and leaves MCAP to rerun's own loader (two loaders would log it twice) and CSV files to others (a CSV
is too common to claim). The recording is the raw view of ``workbench view LOG --raw``
(:mod:`workbench.viewer.rawlog`) with its blueprint, sent active: the viewer opens on the workbench's layout, as
``workbench view`` does, not on its own automatic grid.

Settings honoured: ``--application-id`` and ``--recording-id`` (the recording's ids; defaults: the raw view's
application id and a new recording), ``--entity-path-prefix`` (in front of ``log/…``), ``--static`` (only what
has no time: the parameters). ``--time_sequence`` / ``--time_duration_nanos`` / ``--time_timestamp_nanos`` are
accepted and ignored: a log's samples keep their own clock. A file that is ours but damaged beyond reading
prints ``error: <file>: <cause>`` on stderr and exits 1.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main", "INCOMPATIBLE"]

INCOMPATIBLE = 66  # rerun's EXTERNAL_DATA_LOADER_INCOMPATIBLE_EXIT_CODE, without importing rerun to say no


def _parser() -> argparse.ArgumentParser:
    import os

    called = os.path.basename(sys.argv[0]) if sys.argv else ""
    prog = called if called.startswith("rerun-") else "rerun-importer-workbench"
    p = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    p.add_argument("filepath")
    p.add_argument("--application-id")
    p.add_argument("--opened-application-id")
    p.add_argument("--recording-id")
    p.add_argument("--opened-recording-id")
    p.add_argument("--entity-path-prefix", default="")
    p.add_argument("--static", action="store_true")
    p.add_argument("--timeless", action="store_true")  # the older name of --static
    for name in ("--time_sequence", "--time_duration_nanos", "--time_timestamp_nanos", "--time", "--sequence"):
        p.add_argument(name, action="append", default=[])
    return p


def _ours(path: str) -> bool:
    """Whether the file is a log this loader reads: recognised by its first bytes, not by its name."""
    import os

    if not os.path.isfile(path):
        return False
    from adapters.formats import detect_format
    from workbench.errors import WorkbenchError

    try:
        return detect_format(path).rerun_importer
    except WorkbenchError:
        return False


def main(argv: list[str] | None = None) -> int:
    """Run the loader; returns the exit code (66 for a file that is not ours)."""
    args, _ = _parser().parse_known_args(argv)  # a newer viewer may pass settings this version does not know
    if not _ours(args.filepath):
        return INCOMPATIBLE
    import adapters
    from adapters.rawlog import raw_log
    from workbench.errors import WorkbenchError
    from workbench.viewer.rawlog import RAW_APPLICATION_ID, log_raw, raw_blueprint

    try:
        raw = raw_log(adapters.read(args.filepath))
    except WorkbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    import rerun as rr

    rec = rr.RecordingStream(args.application_id or RAW_APPLICATION_ID, recording_id=args.recording_id)
    rec.stdout()
    prefix = "/".join(p for p in (args.entity_path_prefix.strip("/"), "log") if p)
    logged = log_raw(rec, raw, prefix=prefix, static=args.static or args.timeless)
    rec.send_blueprint(raw_blueprint(logged), make_active=True, make_default=True)
    rec.flush()
    return 0


def run() -> None:
    """The console-script entry point."""
    sys.exit(main())


if __name__ == "__main__":
    run()
