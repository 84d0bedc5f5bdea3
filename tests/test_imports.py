"""Each command imports what it uses, no more (issue 27: a warm ``btlog ask`` answers in
at most 0.3 s, and most of its time went to imports).

Each test runs one real command in a subprocess and then reads which modules the process
holds: the third-party packages (those under site-packages, beyond what a bare
interpreter loads) must be within the command's allowed set, and none of the btlog
modules the command has no use for may be there. A command that starts importing more
fails here, whatever the machine's speed (no timing is measured).
"""

from __future__ import annotations

import functools
import json
import os
import pty
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from tests.cli_support import ROOT, btlog_environment

RECORDING = ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"
TREE = ROOT / "trees" / "kitting.xml"

#: Writes the third-party packages (under site-packages) and every module this process
#: holds as JSON to the file named first; ``_RUN`` runs ``btlog ARGV`` before.
_HELD = """
import json, sys
site = tuple(p for p in sys.path if p.endswith("site-packages"))
packages = {
    name.split(".")[0]
    for name, module in list(sys.modules.items())
    if (getattr(module, "__file__", None) or "").startswith(site)
}
with open(sys.argv[1], "w") as out:
    json.dump({"code": code, "packages": sorted(packages), "modules": sorted(sys.modules)}, out)
"""
_RUN = "import sys\nfrom btlog.cli.main import main\ncode = main(sys.argv[2:])\n"

#: What every command may import from site-packages: DuckDB and the MCAP reading stack.
READING = {"duckdb", "_duckdb", "orjson", "zstandard", "lz4", "mcap"}
#: rich draws trees, tables and timelines on a terminal.
DRAWING = {"rich"}
#: YAML and JSON Schema (with jsonschema's own dependencies), for the documents users write
#: (outcomes, expectations, descriptions).
DOCUMENTS = {
    "yaml",
    "jsonschema",
    "jsonschema_specifications",
    "referencing",
    "rpds",
    "attr",
    "attrs",
    "typing_extensions",
}
#: The btlog modules a command that only reads a cached run never needs: building the
#: read model, loading or executing trees, documents, importers, the viewer and the
#: fleet, the other commands' modules.
NOT_FOR_READING = (
    "btlog.replay.ingest",
    "btlog.replay.load",
    "btlog.replay.scan",
    "btlog.record.recorder",
    "btlog.record.recovery",
    "btlog.tree.loader",
    "btlog.tree.builder",
    "btlog.documents",
    "btlog.domains",
    "btlog.executor.engine",
    "btlog.executor.behavior",
    "btlog.runner",
    "btlog.live_questions",
    "btlog.checks",
    "btlog.sources.",
    "btlog.sinks",
    "btlog.view",
    "btlog.fleet",
    "btlog.cli.checks",
    "btlog.cli.view",
    "btlog.cli.replay",
)
#: Never imported by any command below (the live attach's and the interactive replay's
#: libraries, ROS 2 decoding).
NEVER = ("zmq", "prompt_toolkit", "mcap_ros2", "pyspark")


@functools.cache
def _bare_packages() -> frozenset[str]:
    """The third-party packages a bare interpreter loads (``.pth`` hooks of site-packages)."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "bare.json"
        code = "code = 0\n" + _HELD
        subprocess.run([sys.executable, "-c", code, str(out)], env=btlog_environment(), check=True)
        return frozenset(json.loads(out.read_text())["packages"])


def _imports(
    folder: Path, *argv: str | Path, terminal: bool = False
) -> tuple[int, set[str], list[str]]:
    """(exit code, third-party packages beyond a bare interpreter's, every module) of
    ``btlog ARGV`` run in a subprocess in ``folder``, with its own cache folder there (so
    whether a cache is warm does not depend on the other tests); ``terminal``: its
    standard error is a terminal (a pty), as a user's is."""
    out = folder / "imports.json"
    leader, follower = pty.openpty() if terminal else (None, None)
    try:
        subprocess.run(
            [sys.executable, "-c", _RUN + _HELD, str(out), *map(str, argv)],
            cwd=folder,
            env=btlog_environment({"BTLOG_CACHE_DIR": str(folder / "cache")}),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL if follower is None else follower,
            check=False,
            timeout=300,
        )
    finally:
        for descriptor in (leader, follower):
            if descriptor is not None:
                os.close(descriptor)
    found = json.loads(out.read_text())
    return found["code"], set(found["packages"]) - _bare_packages(), found["modules"]


#: Light modules the command line's parser imports for its defaults, whatever the command.
PARSER = {"btlog.sources.tick_gap"}


def _unneeded(modules: list[str], names: tuple[str, ...]) -> list[str]:
    """The ``modules`` that are, or are inside, one of ``names`` (a name ending in a dot
    matches only the modules inside it), the parser's own (``PARSER``) apart."""
    return [
        m
        for m in modules
        if m not in PARSER
        if any(
            m.startswith(n) if n.endswith(".") else m == n or m.startswith(n + ".") for n in names
        )
    ]


def _check(
    folder: Path, argv: tuple[str | Path, ...], allowed: set[str], unneeded: tuple[str, ...] = ()
) -> list[str]:
    """Run ``btlog ARGV``: it succeeds, its third-party packages are within ``allowed``
    and it imports none of ``unneeded`` nor ``NEVER``; returns its modules."""
    code, packages, modules = _imports(folder, *argv)
    assert code == 0, argv
    assert packages - allowed == set(), f"btlog {argv[0]} imports more than it needs"
    assert _unneeded(modules, (*unneeded, *NEVER)) == [], f"btlog {argv[0]}"
    return modules


@pytest.fixture(scope="module")
def warm(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder in which the bundled recording's cache (tables and snapshots) was built:
    the commands run in it read the cache warm, as a user's second question does."""
    folder = tmp_path_factory.mktemp("warm")
    code, _packages, _modules = _imports(
        folder, "ask", RECORDING, "--at", "end", "What are you doing?"
    )
    assert code == 0
    return folder


@pytest.mark.parametrize(
    "command",
    [
        "run",
        "ask",
        "explain",
        "show",
        "timeline",
        "replay",
        "sql",
        "diff",
        "check",
        "import",
        "export",
        "attach",
        "record-py",
        "cache",
        "view",
        "recover",
        "validate",
        "fleet",
    ],
)
def test_help_imports_no_library(tmp_path: Path, command: str) -> None:
    """Parsing the command line, and any ``--help``, imports no third-party package and
    none of btlog beyond the command line's own light modules."""
    code, packages, modules = _imports(tmp_path, command, "--help")
    assert code == 0
    assert packages == set()
    heavy = ("btlog.replay", "btlog.explain", "btlog.tree.", "btlog.record.", "btlog.executor")
    assert _unneeded(modules, heavy + NOT_FOR_READING) == []


def test_a_first_ask_builds_without_drawing_or_documents(tmp_path: Path) -> None:
    """A first ``ask`` builds the read model (pyarrow) but draws nothing on a pipe."""
    modules = _check(
        tmp_path,
        ("ask", RECORDING, "--at", "12s", "What are you doing?"),
        {*READING, "pyarrow"},
        tuple(m for m in NOT_FOR_READING if not m.startswith(("btlog.replay", "btlog.record"))),
    )
    assert "btlog.replay.ingest" in modules  # the cache was built by this run


@pytest.mark.parametrize(
    "argv",
    [
        ("ask", RECORDING, "--at", "12s", "What are you doing?"),
        ("ask", RECORDING, "--at", "end", "What went wrong?", "--json"),
        ("explain", RECORDING),
        ("explain", RECORDING, "--at", "12s", "--json"),
        ("timeline", RECORDING, "--to", "1s", "--json"),
        ("sql", RECORDING, "SELECT count(*) FROM transitions", "--format", "csv"),
    ],
    ids=["ask", "ask-json", "explain", "explain-at", "timeline-json", "sql-csv"],
)
def test_warm_answers_read_without_pyarrow_or_rich(warm: Path, argv: tuple) -> None:
    """Answers from a cached run: DuckDB and the MCAP reader only; no pyarrow (it builds
    the read model), no rich (nothing is drawn), no tree loader, documents, executor,
    importer, viewer or fleet."""
    _check(warm, argv, READING, NOT_FOR_READING)


def test_a_warm_ask_on_a_terminal_draws_nothing(warm: Path) -> None:
    """On a terminal a first open shows a spinner while the cache is built; a warm one has
    nothing to wait for, so it shows nothing and does not import rich."""
    argv = ("ask", RECORDING, "--at", "12s", "What are you doing?")
    code, packages, _modules = _imports(warm, *argv, terminal=True)
    assert code == 0
    assert packages <= READING


@pytest.mark.parametrize(
    "argv",
    [
        ("show", RECORDING, "--at", "12s", "--plain"),
        ("timeline", RECORDING, "--to", "1s", "--plain"),
        ("sql", RECORDING, "SELECT count(*) FROM transitions"),
    ],
    ids=["show", "timeline", "sql-table"],
)
def test_warm_drawings_add_only_rich(warm: Path, argv: tuple) -> None:
    """What is drawn on a terminal adds rich, nothing else."""
    _check(warm, argv, READING | DRAWING, NOT_FOR_READING)


def test_replay_script_needs_no_prompt(warm: Path) -> None:
    """``replay --script`` reads its commands from a file: no prompt_toolkit."""
    script = warm / "script.txt"
    script.write_text("next\ntree\nq\n", encoding="utf-8")
    allowed = READING | DRAWING
    _check(
        warm,
        ("replay", RECORDING, "--script", script, "--plain"),
        allowed,
        tuple(m for m in NOT_FOR_READING if m != "btlog.cli.replay"),
    )


def test_cache_listing_reads_no_recording(warm: Path) -> None:
    """``cache`` lists files: DuckDB only, none of the reader, explanations or drawing."""
    _check(
        warm,
        ("cache", "--json"),
        {"duckdb", "_duckdb"},
        (*NOT_FOR_READING, "btlog.explain", "btlog.replay.run", "btlog.record"),
    )


def test_run_and_validate_need_no_read_model(tmp_path: Path) -> None:
    """``run`` and ``validate`` load and execute a tree: no DuckDB or pyarrow, no
    importer, viewer, fleet or checks."""
    outside = (
        "btlog.replay.database",
        "btlog.replay.ingest",
        "btlog.checks",
        "btlog.sources.",
        "btlog.sinks",
        "btlog.view",
        "btlog.fleet",
        "btlog.cli.checks",
    )
    allowed = {"orjson", "zstandard", "lz4", "mcap", *DOCUMENTS}
    _check(
        tmp_path,
        ("run", TREE, "--domain", "kitting", "-o", tmp_path / "r.mcap", "--quiet"),
        allowed | DRAWING,
        outside,
    )
    _check(tmp_path, ("validate", TREE), allowed, outside)


def test_export_and_import_need_no_read_model(tmp_path: Path) -> None:
    """``export --to btlog`` and ``import`` of what it wrote: the reader, the recorder and
    their format's modules; no DuckDB, pyarrow, rich, executor, viewer or fleet."""
    outside = (
        "btlog.replay",
        "btlog.explain",
        "btlog.executor",
        "btlog.runner",
        "btlog.checks",
        "btlog.view",
        "btlog.fleet",
        "btlog.sources.groot2",
        "btlog.sources.attach",
    )
    log = tmp_path / "run.btlog"
    _check(
        tmp_path,
        ("export", RECORDING, "--to", "btlog", log),
        {"orjson", "zstandard", "lz4", "mcap", "lxml"},
        outside,
    )
    _check(
        tmp_path,
        ("import", log, "-o", tmp_path / "back.mcap"),
        {"orjson", "zstandard", "lz4", "mcap", *DOCUMENTS},
        outside,
    )


def test_view_export_and_fleet_stay_apart(warm: Path) -> None:
    """``view --export`` writes a page without the fleet or a server's dependencies;
    ``fleet`` on an empty lake fails without the viewer."""
    _check(
        warm,
        ("view", RECORDING, "--export", warm / "page.html"),
        READING | DOCUMENTS,
        ("btlog.fleet", "btlog.sources.", "btlog.cli.checks", "pyarrow"),
    )
    code, _packages, modules = _imports(warm, "fleet", warm / "no-lake")
    assert code == 2
    assert (
        _unneeded(modules, ("btlog.view", "btlog.executor.engine", "btlog.sources.", *NEVER)) == []
    )
