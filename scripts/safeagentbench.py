"""SafeAgentBench for a clone that has no ``../shared``: ``make benchmarks``.

Upstream SafeAgentBench (Yin et al., MIT licence) keeps its tasks in
``dataset/`` of its repository, one JSON Lines file per task type
(``unsafe_detailed_1009.jsonl``, ``safe_detailed_1009.jsonl``,
``abstract_1009.jsonl``, ``long_horizon_1009.jsonl``), every room in the
same file.  VIRF's Makefile, documentation and recorded agent runs use a
development split of it, laid out as ``../shared/benchmarks/safeagentbench``
is on the project's machines::

    DIR/unsafe_detailed.jsonl  safe_detailed.jsonl  abstract.jsonl  long_horizon.jsonl
        the kitchen tasks of the split (FloorPlan1-30)
    DIR/other_rooms/  the same four files: living rooms, bedrooms, bathrooms

Each task is its upstream JSON object with ``source_index``, its 0-based
line in the upstream file, added last.  The tasks left out are held out for
measurement.  Which lines each file takes, and the sha256 of each file, are
recorded in ``safeagentbench_split.json`` beside this script: the files
arranged from a fetch must have those digests, so a replay recorded on the
split (``make agents-report``, whose task ids are file:line of these files)
is never handed other tasks.

    fetch --repo URL --commit SHA --out DIR   clone URL at SHA into DIR/upstream
                                              and arrange the split in DIR
    check DIR [--exists]                      DIR holds the recorded split
                                              (--exists: the eight files, any content)
    record DIR                                rewrite the record from a split in DIR

Standard library and git only: it runs before any virtualenv exists.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

RECORD = Path(__file__).resolve().with_name("safeagentbench_split.json")
TYPES = ("unsafe_detailed", "safe_detailed", "abstract", "long_horizon")
# Where each part of the split goes, relative to DIR.
PARTS = {"kitchens": "", "other_rooms": "other_rooms/"}


class Failure(Exception):
    """One line for the user; the script exits 1 with it."""


def _files() -> list[str]:
    return [f"{prefix}{kind}.jsonl" for prefix in PARTS.values() for kind in TYPES]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _load_record() -> dict[str, Any]:
    try:
        record: dict[str, Any] = json.loads(RECORD.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise Failure(f"cannot read {RECORD}: {exc}") from None
    return record


def _git(where: Path, *args: str) -> str:
    try:
        done = subprocess.run(
            ["git", "-C", str(where), *args], capture_output=True, text=True, check=False
        )
    except FileNotFoundError:
        raise Failure("git is not installed (apt-get install git)") from None
    if done.returncode != 0:
        lines = [line.strip() for line in done.stderr.splitlines() if line.strip()]
        # git's own reason is its fatal: line; hints follow it.
        reason = next((x for x in lines if x.startswith(("fatal:", "error:"))), None)
        shown = reason or (lines[-1] if lines else f"exit {done.returncode}")
        raise Failure(f"git {args[0]} failed: {shown}")
    return done.stdout.strip()


def clone_at(repo: str, commit: str, clone: Path) -> None:
    """``clone`` holds ``repo`` checked out at ``commit`` (fetched once)."""
    if not re.fullmatch(r"[0-9a-f]{40}", commit):
        raise Failure(f"SAB_COMMIT must be a full 40-digit commit hash, not '{commit}'")
    clone.mkdir(parents=True, exist_ok=True)
    if not (clone / ".git").exists():
        _git(clone, "init", "-q")
    try:
        _git(clone, "fetch", "-q", "--depth", "1", repo, commit)
    except Failure:
        # A server that refuses a commit by hash still gives its branches.
        _git(clone, "fetch", "-q", repo)
        try:
            _git(clone, "cat-file", "-e", f"{commit}^{{commit}}")
        except Failure:
            raise Failure(f"{repo} has no commit {commit}") from None
    _git(clone, "checkout", "-q", "--detach", commit)
    head = _git(clone, "rev-parse", "HEAD")
    if head != commit:
        raise Failure(f"{clone} is at {head}, not at {commit}")


def _upstream_file(dataset: Path, kind: str) -> Path:
    found = sorted(dataset.glob(f"{kind}*.jsonl"))
    if len(found) != 1:
        there = sorted(p.name for p in dataset.glob("*.jsonl")) if dataset.is_dir() else []
        what = "none" if not found else ", ".join(p.name for p in found)
        raise Failure(
            f"expected one {kind}*.jsonl in {dataset}, found {what}; "
            f"it has: {', '.join(there) or 'no JSON Lines files'}"
        )
    return found[0]


def arrange(dataset: Path, out: Path, split: dict[str, dict[str, list[int]]]) -> None:
    """Write the split's files into ``out`` from the upstream ``dataset/``."""
    for kind in TYPES:
        source = _upstream_file(dataset, kind)
        lines = source.read_text(encoding="utf-8").splitlines()
        for part, prefix in PARTS.items():
            rows = []
            for index in split[kind][part]:
                if index >= len(lines):
                    raise Failure(
                        f"{source.name} has {len(lines)} lines; the split takes line {index}"
                    )
                try:
                    task = json.loads(lines[index])
                except ValueError:
                    raise Failure(f"{source.name} line {index} is not JSON") from None
                rows.append(json.dumps({**task, "source_index": index}) + "\n")
            target = out / f"{prefix}{kind}.jsonl"
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text("".join(rows), encoding="utf-8")


def check(folder: Path, *, exists_only: bool = False) -> None:
    missing = [name for name in _files() if not (folder / name).is_file()]
    if missing:
        raise Failure(
            f"no SafeAgentBench development split in {folder} (missing {missing[0]}): "
            "run 'make benchmarks' to fetch it, or set SAB=DIR to a folder that has it"
        )
    if exists_only:
        return
    digests: dict[str, str] = _load_record()["sha256"]
    differ = [name for name in _files() if _sha256(folder / name) != digests[name]]
    if differ:
        raise Failure(
            f"{folder / differ[0]} is not the development split's file (its sha256 differs"
            f"{f', as do {len(differ) - 1} more' if len(differ) > 1 else ''}): the recorded "
            "agent runs replay only the split they were recorded on"
        )


def record(folder: Path) -> None:
    check(folder, exists_only=True)
    split: dict[str, dict[str, list[int]]] = {}
    for kind in TYPES:
        split[kind] = {}
        for part, prefix in PARTS.items():
            text = (folder / f"{prefix}{kind}.jsonl").read_text(encoding="utf-8")
            split[kind][part] = [json.loads(line)["source_index"] for line in text.splitlines()]
    digests = {name: _sha256(folder / name) for name in _files()}
    # One line per file's list of lines, so a change to the split reads as one.
    kinds = [f"  {json.dumps(kind)}: {json.dumps(split[kind])}" for kind in TYPES]
    sums = [f"  {json.dumps(name)}: {json.dumps(digest)}" for name, digest in digests.items()]
    text = '{\n "split": {\n' + ",\n".join(kinds) + '\n },\n "sha256": {\n'
    RECORD.write_text(text + ",\n".join(sums) + "\n }\n}\n", encoding="utf-8")


def fetch(repo: str, commit: str, out: Path) -> None:
    clone_at(repo, commit, out / "upstream")
    arrange(out / "upstream" / "dataset", out, _load_record()["split"])
    try:
        check(out)
    except Failure as exc:
        raise Failure(
            f"the tasks arranged from {commit} are not the recorded development split "
            f"({exc}); the upstream files differ from those the split was taken from"
        ) from None
    print(f"SafeAgentBench {commit[:12]}: the development split is in {out}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    get = commands.add_parser("fetch", help="fetch upstream at a commit and arrange the split")
    get.add_argument("--repo", required=True)
    get.add_argument("--commit", required=True)
    get.add_argument("--out", type=Path, required=True)
    test = commands.add_parser("check", help="a folder holds the recorded split")
    test.add_argument("folder", type=Path)
    test.add_argument("--exists", action="store_true", help="only that its eight files exist")
    keep = commands.add_parser("record", help="record the split a folder holds")
    keep.add_argument("folder", type=Path)
    args = parser.parse_args(argv)
    try:
        if args.command == "fetch":
            fetch(args.repo, args.commit, args.out)
        elif args.command == "check":
            check(args.folder, exists_only=args.exists)
        else:
            record(args.folder)
    except Failure as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
