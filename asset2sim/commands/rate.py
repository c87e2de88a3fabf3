"""``asset2sim rate FOLDER``: the realism rating app for people over a pair set (``FOLDER/pairs.json``, or
``FOLDER/realism/pairs.json`` of a run's output folder), served on 127.0.0.1 until Ctrl-C; answers land in
``ratings.sqlite`` and ``ratings.parquet`` beside ``pairs.json``. ``--scores`` instead prints the
Bradley-Terry scores per method, writes ``realism_scores.parquet`` there and, with ``--tracking-uri``, logs
them to MLflow.

Exit status: 0 done (or stopped with Ctrl-C), 1 no pair set or an invalid one, or a damaged ``ratings.sqlite``
(``RATINGS_DATABASE_DAMAGED``, left as it is), 2 a bad option, 3 nothing rated yet (``--scores``), 4 the port or
the folder cannot be used.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from asset2sim.commands._status import INVALID_INPUT, OUTPUT_LOCATION, CommandError
from asset2sim.apps.realism.rating_app import serve
from asset2sim.apps.realism.pair_set import PairSetError, find_pair_set
from asset2sim.apps.realism.ratings import RATINGS_FILE
from asset2sim.apps.realism.scores import SCORES_FILE, realism_scores
from asset2sim.commands import _output
from asset2sim.inert import markup

NAME = "rate"
HELP = ("Serve the realism rating app for people over a pair set (FOLDER/pairs.json or FOLDER/realism/pairs.json) "
        "on 127.0.0.1, or with --scores print the Bradley-Terry scores per method (docs/guide/realism.md).")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "done (or stopped with Ctrl-C)",
    1: "no pair set, an invalid one or a damaged ratings.sqlite",
    3: "nothing rated yet (--scores)",
    4: "the port or the folder cannot be used",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=Path, metavar="FOLDER",
                   help="a pair-set folder (holding pairs.json) or an output folder holding realism/pairs.json")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8765, help="port to listen on (default 8765)")
    p.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                   help="another host name raters' browsers use to reach the app (with --host 0.0.0.0, e.g. the "
                        "machine's name); requests naming any other host are refused (repeatable)")
    p.add_argument("--scores", action="store_true",
                   help="instead of serving: print the Bradley-Terry scores of the ratings so far, "
                        "write realism_scores.parquet")
    p.add_argument("--tracking-uri",
                   help="with --scores: also log the scores to this MLflow tracking store (e.g. sqlite:///mlflow.db)")


def pair_set_folder(folder: Path) -> Path:
    """``folder`` when it holds ``pairs.json``, else ``folder/realism`` when that does (CommandError status 1
    ``PAIRS_MISSING`` otherwise)."""
    try:
        return find_pair_set(folder)
    except PairSetError as exc:
        raise CommandError(INVALID_INPUT, "PAIRS_MISSING", folder, f"{exc} (docs/guide/realism.md)") from None


def run(args: argparse.Namespace) -> int:
    if not 0 < args.port < 65536:
        raise CommandError.invalid("PORT_INVALID", f"--port must be 1-65535, got {args.port}")
    if args.tracking_uri and not args.scores:
        raise CommandError.invalid("TRACKING_WITHOUT_SCORES", "--tracking-uri goes with --scores")
    folder = pair_set_folder(args.folder)
    if args.scores:
        return _scores(folder, args.tracking_uri)
    # a browser must name a host the app answers to: every interface is reached here as 127.0.0.1
    shown = "127.0.0.1" if args.host in ("", "0.0.0.0", "::") else args.host
    shown = f"[{shown}]" if ":" in shown else shown
    print(f"rating app for {folder}: http://{shown}:{args.port}/  (Ctrl-C stops)", flush=True)
    try:
        serve(folder, host=args.host, port=args.port, allowed_hosts=args.allow_host)
    except KeyboardInterrupt:  # uvicorn stopped gracefully (ratings.parquet synced) and re-raised Ctrl-C
        pass
    except SystemExit as exc:  # uvicorn could not start (the port taken): it logged why
        raise CommandError(OUTPUT_LOCATION, "PORT_UNAVAILABLE", None,
                           f"cannot listen on {args.host}:{args.port} (in use or not allowed)") from exc
    print(f"stopped; ratings in {folder / RATINGS_FILE}", flush=True)
    return 0


def _scores(folder: Path, tracking_uri: str | None) -> int:
    from rich.table import Table

    scores = realism_scores(folder)
    table = Table("method", title=f"realism (Bradley-Terry, people) of {markup(folder)}")
    for column in ("strength", "95 % interval", "Elo", "wins", "comparisons"):
        table.add_column(column, justify="right")
    for s in scores:
        table.add_row(markup(s.method), f"{s.strength:+.2f}", f"[{s.ci_low:+.2f}, {s.ci_high:+.2f}]", f"{s.elo:.0f}",
                      str(s.wins), str(s.comparisons))
    _output.console().print(table)
    print(f"written: {folder / SCORES_FILE}")
    if tracking_uri:
        from asset2sim.flows.realism_tracking import REALISM_EXPERIMENT, log_realism_scores  # MLflow: only when asked

        run_id = log_realism_scores(scores, tracking_uri=tracking_uri, experiment=REALISM_EXPERIMENT,
                                    ratings_parquet=folder / RATINGS_FILE)
        print(f"MLflow run {run_id} (experiment {REALISM_EXPERIMENT}) at {tracking_uri}")
    return 0
