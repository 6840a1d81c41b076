"""Rebuild the household rules from their knowledge-acquisition record.

``knowledge/household/`` holds what the workflow needs to be replayed: the
drafts (``drafts/*.json``, each a document ``virf kb propose`` reads, citing
starter-corpus passages) and the arbitration (``decisions.jsonl``, one line
per rule: accept or reject, who decided, why, and an edited axiom if the
reviewer changed it).  This script runs the real workflow on them:

1. ``virf kb init`` a workspace layered on the ``base`` scenario (the
   vocabulary and hazard mechanisms, no hazard rules) with the starter corpus;
2. propose every draft (normalisation, HermiT consistency, satisfiability,
   novelty against the rules accepted before it);
3. decide every candidate as recorded (an accepted candidate is checked once
   more, exactly as ``virf kb decide`` does);
4. export the accepted blocks as ``src/virf/ontology/modules/safety-acquired.omn``,
   which every room scenario imports.

    python scripts/build_household_kb.py            # rebuild the module
    python scripts/build_household_kb.py --check    # exit 1 if the module differs

Run ``python -m virf.ontology.compile`` afterwards to refresh the artifacts
(``make kb-household`` does both).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "knowledge" / "household"
MODULE = ROOT / "src" / "virf" / "ontology" / "modules" / "safety-acquired.omn"
IRI = "http://virf.dev/ontology/safety-acquired"
LABEL = (
    "VIRF rules acquired from safety documents through the knowledge-acquisition workflow "
    "(rebuilt from knowledge/household by scripts/build_household_kb.py)"
)
# The date of a decision is when the replay ran, not part of the knowledge.
_DATE = re.compile(r':decidedOn "\d{4}-\d{2}-\d{2}"')


def load_decisions(path: Path) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise SystemExit(f"{path}:{n}: not a JSON object ({exc.msg})") from None
        name = rec.get("rule") if isinstance(rec, dict) else None
        if not isinstance(name, str) or rec.get("decision") not in ("accept", "reject"):
            raise SystemExit(f"{path}:{n}: needs 'rule' and 'decision' (accept or reject)")
        if name in out:
            raise SystemExit(f"{path}:{n}: a second decision for {name}")
        out[name] = rec
    return out


def build(workspace: Path, record: Path = RECORD) -> str:
    from virf.authoring.workspace import Workspace
    from virf.errors import InputError

    if workspace.exists():
        # Only a workspace (or an empty folder) is replaced, never anything else.
        if any(workspace.iterdir()) and not (workspace / "virf-kb.json").is_file():
            raise SystemExit(f"{workspace} is not a knowledge workspace; give a new folder")
        shutil.rmtree(workspace)
    ws = Workspace.init(workspace, scenario="base")
    decisions = load_decisions(record / "decisions.jsonl")
    drafts = sorted((record / "drafts").glob("*.json"))
    seen: set[str] = set()
    try:
        for path in drafts:
            try:
                meta = json.loads(path.read_text(encoding="utf-8"))
            except json.JSONDecodeError as exc:
                raise SystemExit(f"{path}: not a JSON draft ({exc.msg})") from None
            author = str(meta.get("drafter", "virf-engineers")) if isinstance(meta, dict) else ""
            # Checked once, when the decision is taken (an acceptance re-checks
            # the final axiom and stores the result), not twice.
            try:
                cids = ws.propose(path, author or "virf-engineers", check=False)
            except InputError as exc:
                raise SystemExit(f"{path.name}: {exc}") from None
            for cid in cids:
                row = ws.store.candidate(cid)
                rec = decisions.get(row.name)
                if rec is None:
                    raise SystemExit(f"{path.name}: no decision recorded for {row.name}")
                seen.add(row.name)
                try:
                    if rec["decision"] == "reject":
                        ws.check(cid)  # the audit shows what the checks said of it
                    ws.decide(
                        cid,
                        rec["decision"],
                        reviewer=rec.get("reviewer", "virf-engineers"),
                        reason=rec.get("reason"),
                        axiom=rec.get("axiom"),
                    )
                except InputError as exc:
                    raise SystemExit(f"{path.name}: {row.name}: {exc}") from None
                print(f"{cid:3d} {rec['decision']:6s} {row.name}", file=sys.stderr)
        stray = sorted(set(decisions) - seen)
        if stray:
            raise SystemExit(f"decisions.jsonl decides {stray[0]}, which no draft proposes")
        return ws.export(IRI, LABEL)
    finally:
        ws.close()


def comparable(text: str) -> str:
    return _DATE.sub(':decidedOn "-"', text)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workspace", type=Path, default=None, help="keep the workspace here")
    parser.add_argument("--check", action="store_true", help="compare with the committed module")
    parser.add_argument("--record", type=Path, default=RECORD, help="drafts/ and decisions.jsonl")
    parser.add_argument("--out", type=Path, default=MODULE, help="the module to write or check")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        text = build(args.workspace or Path(tmp) / "kb-household", args.record)
    out: Path = args.out
    if args.check:
        same = out.is_file() and comparable(out.read_text(encoding="utf-8")) == comparable(text)
        print(f"{out} {'matches' if same else 'DIFFERS FROM'} the record")
        return 0 if same else 1
    from virf.files import write_atomically

    write_atomically(out, text)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
