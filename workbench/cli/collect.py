"""``workbench collect``: serve the experiment's page on 127.0.0.1 and write each finished trial into DIR; or
exclude a trial of a session from the analysis (``--exclude ID --note TEXT``).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import sys
from pathlib import Path
from typing import Any

from workbench.cli.context import Context
from workbench.cli.options import horizon_arg, seed_arg
from workbench.defaults import HORIZON_S

__all__ = ["cmd_collect", "add_collect"]


def add_collect(add: Any) -> None:
    """Register ``collect`` with the parser's ``add`` (see :func:`workbench.cli.parser.build_parser`)."""
    p = add("collect", cmd_collect, "run the paper's landing experiment in the browser; each trial is written to DIR "
            "as it ends", "workbench collect --protocol paper_single_subject --out session/ && workbench fit session/ "
            "--label CS1 -o cs1.npz")
    p.add_argument("--protocol", metavar="NAME|FILE.toml",
                   help="the experiment: paper_single_subject, paper_multi_subject, assisted_single_subject or a "
                        "protocol TOML file")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the session folder: a dataset `workbench fit DIR` reads; an existing session of the same "
                        "protocol is resumed, one of another protocol refused")
    p.add_argument("--new-session", action="store_true",
                   help="DIR holds a session of another protocol: start a new one there (the old one is moved to "
                        "DIR/_collect/previous/, nothing deleted)")
    p.add_argument("--port", type=_port, default=8765, help="port on 127.0.0.1 (default 8765; 0: a free one)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only; another address lets other "
                        "machines reach the page, through a link with a token that the command prints)")
    p.add_argument("--no-browser", action="store_true", help="do not open the page in a browser")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the trials' start positions (default 0)")
    v = p.add_argument_group("the experimenter's view (rerun): the trials as they fly, outcomes, fits, a summary "
                             "per subject")
    x = v.add_mutually_exclusive_group()
    x.add_argument("--save", metavar="FILE.rrd", help="write the session's recording when the server stops")
    x.add_argument("--spawn", action="store_true", help="stream it to a native rerun viewer")
    x.add_argument("--serve", action="store_true", help="serve a web viewer of it on 127.0.0.1")
    v.add_argument("--model", action="append", metavar="LABEL=MODEL.npz",
                   help="a fitted model of a block label (repeatable): it assists that label's assisted blocks that "
                        "have no fit step, and its prediction from each trial's start is drawn beside the live track")
    v.add_argument("--horizon", dest="horizon_s", type=horizon_arg, default=HORIZON_S, metavar="SECONDS",
                   help="length of that prediction (default %(default)s s)")
    e = p.add_argument_group("exclusion (no server: marks a trial of DIR in its own metadata and in trials.csv)")
    e.add_argument("--exclude", metavar="TRIAL_ID", help="exclude this trial from the analysis (needs --note)")
    e.add_argument("--include", metavar="TRIAL_ID", help="include an excluded trial again")
    e.add_argument("--note", default="", help="why (kept with the trial as exclusion_note)")
    g = p.add_argument_group("shortening (demonstrations and tests; a real session runs the protocol as written)")
    g.add_argument("--max-trials", type=_positive_int, metavar="N", help="at most N trials per block")
    g.add_argument("--max-pause", type=_seconds, metavar="SECONDS", help="breaks and practice at most this long")


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def _port(text: str) -> int:
    value = _integer(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"a port is 0 to 65535, got {value}")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not 0 <= value < float("inf"):  # also refuses nan, which min() would pass over
        raise argparse.ArgumentTypeError(f"must be 0 or more seconds, got {text}")
    return value


def _positive_int(text: str) -> int:
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _exclusion(ctx: Context) -> int:
    from workbench.collect.records import set_exclusion
    from workbench.errors import UsageError

    a = ctx.args
    if a.exclude and a.include:
        raise UsageError("--exclude and --include: one trial at a time")
    if a.exclude and not a.note.strip():
        raise UsageError("--exclude needs --note saying why (it is kept with the trial)")
    trial = a.exclude or a.include
    row = set_exclusion(Path(a.out), trial, bool(a.exclude), a.note)
    state = "excluded" if row["excluded"] else "included again"
    ctx.say(f"{trial}: {state}" + (f" ({row['exclusion_note']})" if row["exclusion_note"] else "")
            + f"; {Path(a.out) / '_collect' / 'trials.csv'} updated")
    return 0


def cmd_collect(ctx: Context) -> int:
    from workbench.collect.guard import LOCAL_HOSTS, allowed_hosts
    from workbench.collect.protocol import load_protocol
    from workbench.collect.server import Server, make_app, new_token
    from workbench.collect.session import Session
    from workbench.errors import UsageError

    a = ctx.args
    if a.exclude or a.include:
        return _exclusion(ctx)
    if not a.protocol:
        raise UsageError("collect needs --protocol (or --exclude/--include TRIAL_ID to mark a trial of --out)")
    protocol = load_protocol(a.protocol)
    if a.max_trials is not None or a.max_pause is not None:
        protocol = protocol.shortened(a.max_trials, a.max_pause)
    models, digests = _models(a.model or [])
    view = None

    def on_event(kind: str, text: str) -> None:
        if kind == "warning":
            print(f"warning: {text}", file=sys.stderr, flush=True)
        else:
            ctx.say(text)
        if view is not None:
            view.event(kind, text)

    session = Session(a.out, protocol, seed=a.seed, models=models, model_digests=digests, new_session=a.new_session,
                      on_event=on_event)

    def on_trial(out: dict[str, Any], payload: dict[str, Any]) -> None:
        ctx.say(f"{out['subject']}: {out['id']} {out['outcome_reason']} ({out['samples']} samples); "
                f"{out['trials_done']} of {out['trials_total']} trials done")
        if view is not None:
            view.trial(out, payload, out)

    local = a.host in LOCAL_HOSTS
    token = None if local else new_token()
    key = new_token()
    saved = None
    with contextlib.ExitStack() as stack:
        if a.save or a.spawn or a.serve:
            from workbench.collect.experimenter import ExperimenterView
            from workbench.viewer import new_recording, open_output

            rec = new_recording("workbench collect")
            saved = None if not a.save else str(ctx.output_path(a.save, ".rrd", "the recording"))
            sink = stack.enter_context(open_output(rec, save=saved, spawn=a.spawn, serve=a.serve))
            view = ExperimenterView(rec, session.spec, models, a.horizon_s, out=str(a.out), saved=saved)
            session.on_fit = view.fit
            if a.serve:
                ctx.say(f"the experimenter's view: {sink.url}")
        server = Server(make_app(session, on_trial=on_trial, on_live=None if view is None else view.live,
                                 hosts=allowed_hosts(a.host), token=token, key=key), a.host, a.port)
        shown_host = a.host if a.host not in ("0.0.0.0", "::") else _machine_name()
        url = server.url_for(shown_host, "" if token is None else f"token={token}")
        n_trials = sum(b.trials for b in protocol.blocks)
        # each link alone on its line, so that it can be copied whole from any terminal
        print(f"serving {url}", flush=True)
        ctx.say(f"the subject's page above: protocol {protocol.name}, {len(protocol.steps)} steps, {n_trials} trials "
                f"per subject; session {a.out}; Ctrl-C stops")
        ctx.say("the experimenter's page (keep the link to yourself):")
        print(server.url_for(shown_host, f"key={key}").replace("/?key", "/experimenter?key"), flush=True)
        if not local:
            print(f"warning: listening on {a.host}: other machines can reach the page; it needs the token in the link "
                  "above", file=sys.stderr)
        if not a.no_browser:
            import webbrowser

            webbrowser.open(url)
        server.run()
        session.fits.wait(5.0)
    if saved is not None:
        ctx.say(f"wrote the experimenter's recording to {saved}")
        ctx.say(f"open it with: rerun {saved}")
    if not session.subjects():
        ctx.say(f"no subject has started; {a.out} holds no trials")
    for subject in session.subjects():
        status = session.status(subject)
        parts = ", ".join(f"{r['label']} {r['role']}{'' if r['assist'] == 'none' else ' ' + r['assist']} "
                          f"{r['landed']}/{r['trials']} landed" for r in session.summary(subject)) or "no trials"
        ctx.say(f"{subject}: {status['trials_done']} of {status['trials_total']} trials ({parts})")
    if session.subjects():
        ctx.say(f"one line per trial: {Path(a.out) / '_collect' / 'trials.csv'}; what each column and key means: "
                f"{Path(a.out) / '_collect' / 'data_dictionary.md'}")
    return 0


def _machine_name() -> str:
    import socket

    return socket.gethostname()


def _models(specs: list[str]) -> tuple[dict[str, Any], dict[str, str]]:
    from workbench.errors import UsageError
    from workbench.models import load_model

    out, digests = {}, {}
    for spec in specs:
        label, eq, path = spec.partition("=")
        if not eq or not label or not path:
            raise UsageError(f"--model {spec}: expected LABEL=MODEL.npz (the block label whose trials it predicts)")
        out[label] = load_model(path)
        digests[label] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return out, digests
