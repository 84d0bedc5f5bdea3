"""``btlog view``: the web viewer of one or two runs, served on 127.0.0.1 or exported."""

from __future__ import annotations

import os
import sys
import threading
import webbrowser
from argparse import Namespace
from pathlib import Path
from typing import TYPE_CHECKING

from btlog.render.escape import safe

if TYPE_CHECKING:  # the read model (DuckDB) is imported when a command needs it
    from btlog.replay.database import RunDatabase
    from btlog.view.model import RunView


def open_views(paths: list[str]) -> tuple[RunDatabase, list[RunView]]:
    """Open the recordings in one read model; one view per recording."""
    from btlog.replay.database import open_runs
    from btlog.view.model import RunView

    database = open_runs(*paths)
    for info in database.runs:
        for warning in info.warnings:
            print(f"btlog: warning: {safe(warning)}", file=sys.stderr)
    labels = [Path(p).name for p in paths]
    if len(set(labels)) < len(labels):
        labels = [f"{'AB'[i]}: {label}" for i, label in enumerate(labels)]
    pairs = zip(paths, labels, strict=True)
    return database, [RunView(database, database.run(path), label) for path, label in pairs]


def write_export(paths: list[str], output: str, report: str | None = None) -> None:
    """Write the self-contained viewer of ``paths`` to ``output``."""
    from btlog.view.export import export_page
    from btlog.view.model import divergence_json

    database, views = open_views(paths)
    try:
        diff = divergence_json(paths[0], paths[1]) if len(paths) == 2 else None
        Path(output).write_text(export_page(views, diff, report), encoding="utf-8")
    finally:
        database.close()


def view(args: Namespace) -> int:
    """``btlog view REC [REC2] [--port P] [--no-browser] [--export FILE]``."""
    from btlog.view.model import divergence_json
    from btlog.view.server import ViewerApp, serve

    paths = [args.run] + ([args.other] if args.other else [])
    if args.export:
        write_export(paths, args.export)
        print(args.export)
        return 0
    database, views = open_views(paths)
    try:
        diff = divergence_json(paths[0], paths[1]) if len(paths) == 2 else None
        server = serve(ViewerApp(views, diff), args.port)
    except OSError as error:
        database.close()
        raise ValueError(f"--port {args.port}: cannot listen: {error.strerror or error}") from None
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    print(f"btlog view: {url}  (Ctrl-C stops it)", flush=True)
    if not args.no_browser and not os.environ.get("BTLOG_NO_BROWSER"):
        threading.Thread(target=webbrowser.open, args=(url,), daemon=True).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("btlog view: stopped", file=sys.stderr)
    finally:
        server.server_close()
        database.close()
    return 0
