"""Regenerate the bundled recordings with today's code, or check that doing so changes
nothing (``--check``, run by the test suite: a recording made by older code fails it).

Each recording is the ``btlog run`` command in ``recordings/README.md``, run from the
project root on the simulated clock, so it is reproducible event for event. Two
recordings of the same run differ only in their run id, start time and btlog version;
``--check`` compares everything else: the metadata, the tree, every event, tick and live
answer.

    python recordings/regenerate.py            # rewrite recordings/*.mcap
    python recordings/regenerate.py --check    # exit 1 naming what regenerating changes
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The bundled recordings and the ``btlog run`` arguments of each (as recordings/README.md).
COMMANDS = {
    "kitting-ok.mcap": ["trees/kitting.xml", "--domain", "kitting", "--seed", "1"],
    "kitting-look-at-chuck-fails.mcap": [
        "trees/kitting.xml", "--domain", "kitting", "--fail", "look at chuck",
        "--ask", "30s=What went wrong?",
    ],
    "kitting-can-you.mcap": [
        "trees/kitting.xml", "--domain", "kitting", "--ask", "20s=Can you insert large gear?",
    ],
    "taxi-optimal.mcap": ["trees/taxi.xml", "--domain", "taxi"],
    "taxi-human.mcap": ["trees/taxi-human.xml", "--domain", "taxi"],
}  # fmt: skip
#: Metadata that differs between two recordings of the same run.
PER_RECORDING = ("run_id", "started_at", "btlog_version")


def record(name: str, output: Path) -> None:
    """``btlog run`` of ``name``'s command into ``output`` (from the project root)."""
    command = [sys.executable, "-m", "btlog.cli.main", "run", *COMMANDS[name], "-o", str(output)]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{name}: btlog run failed: {done.stderr.strip()}")


def content(path: Path) -> dict:
    """What a recording holds beyond its run id, start time and btlog version."""
    from btlog.record import open_recording

    recording = open_recording(path)
    metadata = {k: v for k, v in recording.metadata.items() if k not in PER_RECORDING}
    metadata.pop("tree_file_abs", None)  # where the checkout is
    return {
        "metadata": metadata,
        "tree": recording.tree.describe(),
        "events": [tuple(event) for event in recording.events],
        "ticks": [tuple(tick) for tick in recording.ticks],
        "answers": [{k: v for k, v in a.items() if k != "run_id"} for a in recording.answers],
    }


def differences(old: dict, new: dict) -> list[str]:
    """What differs between two recordings' contents, one line each."""
    found = []
    for key in old:
        if old[key] != new[key]:
            if isinstance(old[key], list):
                found.append(f"{key}: {len(old[key])} recorded, {len(new[key])} regenerated")
            else:
                keys = sorted(
                    k for k in {*old[key], *new[key]} if old[key].get(k) != new[key].get(k)
                )
                found.append(f"{key}: {', '.join(keys)} differ")
    return found


def main(argv: list[str] | None = None) -> int:
    """Regenerate (or ``--check``) the bundled recordings; 1 if a check finds a change."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only say what would change")
    parser.add_argument("names", nargs="*", help="some of the recordings (default: all)")
    args = parser.parse_args(argv)
    stale = []
    with tempfile.TemporaryDirectory(prefix="btlog-regenerate-") as folder:
        for name in args.names or COMMANDS:
            fresh = Path(folder) / name
            record(name, fresh)
            bundled = ROOT / "recordings" / name
            changed = (
                differences(content(bundled), content(fresh)) if bundled.exists() else ["missing"]
            )
            if args.check:
                if changed:
                    stale.append(f"recordings/{name} is stale: " + "; ".join(changed))
            else:
                shutil.copyfile(fresh, bundled)
                print(f"recordings/{name}: " + ("regenerated" if changed else "unchanged"))
    for line in stale:
        print(line)
    if args.check and stale:
        print("regenerate them: python recordings/regenerate.py")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
