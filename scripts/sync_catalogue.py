"""Bring the object catalogue in line with AI2-THOR's own per-type facts.

``../shared/reference/ai2thor-objects.json`` holds, per object type, what
AI2-THOR itself reports at run time over all 120 iTHOR floor plans:
affordances (pickupable, openable, toggleable, sliceable, breakable,
receptacle, fillable, dirtyable, cookable, canBeUsedUp) and salient
materials, with ``_varies`` and ``_salientMaterialsVariants`` where a type's
instances differ.  This script copies those facts into
``src/virf/ontology/data/kitchen_catalogue.json`` and leaves VIRF's own
decisions alone (categories, attributes, start states, receptacle kinds,
compatible receptacles):

* an affordance every instance has (or none has) becomes the catalogue's
  true (false); one that differs between instances is listed in the type's
  ``varies``: it is neither asserted nor refused;
* materials every instance has become the type's materials: strict (a TBox
  axiom) where VIRF already stated them strictly, else typical (a default a
  scene may override); where instances differ, ``material_variants`` lists
  each combination AI2-THOR reports, and the materials only some have are
  possibilities a hazard may not take for granted;
* a type AI2-THOR reports as a receptacle gets a receptacle kind (``surface``
  unless VIRF says otherwise); one it never reports as a receptacle loses it.

    python scripts/sync_catalogue.py                 # rewrite the catalogue
    python scripts/sync_catalogue.py --check         # exit 1 if it disagrees

Run ``python -m virf.ontology.build`` and ``python -m virf.ontology.compile``
afterwards (``make kb``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CATALOGUE = ROOT / "src" / "virf" / "ontology" / "data" / "kitchen_catalogue.json"
REFERENCE = ROOT.parent / "shared" / "reference" / "ai2thor-objects.json"

# catalogue field -> AI2-THOR field
AFFORDANCES = {
    "pickupable": "pickupable",
    "openable": "openable",
    "toggleable": "toggleable",
    "sliceable": "sliceable",
    "breakable": "breakable",
    "dirtyable": "dirtyable",
    "cookable": "cookable",
    "can_fill_with_liquid": "fillable",
    "can_be_used_up": "canBeUsedUp",
}
# Materials VIRF records that AI2-THOR does not report as a salient material
# of the object itself: what a product holds (the soap in a soap bottle).
CONTENT_MATERIALS = frozenset({"Soap"})


def variants(ref: dict[str, Any]) -> list[list[str]] | None:
    """The material combinations of a type whose instances differ, or None."""
    raw = ref.get("_salientMaterialsVariants")
    if not raw:
        return None
    out = []
    for combo in sorted(raw):
        out.append([] if combo == "(none)" else sorted(combo.split("+")))
    return sorted(out)


def synced(name: str, info: dict[str, Any], ref: dict[str, Any]) -> dict[str, Any]:
    """The catalogue entry ``info`` with AI2-THOR's facts ``ref`` applied."""
    new = dict(info)
    varying = set(ref.get("_varies") or {})
    fields = {ai: ours for ours, ai in AFFORDANCES.items()}
    varies = sorted(fields[k] for k in varying if k in fields)
    for ours, ai in AFFORDANCES.items():
        value = ref.get(ai)
        if ours in varies:
            new[ours] = True  # some instances afford it: never refused
        elif value is not None:
            new[ours] = bool(value)
    receptacle = ref.get("receptacle")
    if "receptacle" in varying:
        varies.append("receptacle")
        new["receptacle"] = info.get("receptacle") or "surface"
    elif receptacle is True and not info.get("receptacle"):
        new["receptacle"] = "surface"
    elif receptacle is False:
        new["receptacle"] = None
    new["varies"] = sorted(varies)
    combos = variants(ref)
    salient = ref.get("salientMaterials")
    if salient is not None or combos:
        certain = (
            sorted(set.intersection(*(set(c) for c in combos))) if combos else sorted(salient or [])
        )
        kept = [m for m in info.get("materials", []) if m in CONTENT_MATERIALS]
        strict = sorted({m for m in info.get("materials", []) if m in certain} | set(kept))
        new["materials"] = strict
        new["typical_materials"] = [m for m in certain if m not in strict]
        new["material_variants"] = combos or []
    else:
        new.setdefault("material_variants", [])
    return new


def sync(catalogue: dict[str, Any], reference: dict[str, Any]) -> dict[str, Any]:
    types = catalogue["types"]
    out = dict(catalogue)
    out["types"] = {
        name: synced(name, info, reference[name]) if name in reference else info
        for name, info in types.items()
    }
    for info in out["types"].values():
        info.setdefault("varies", [])
        info.setdefault("material_variants", [])
    return out


def differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    lines = []
    for name in sorted(new["types"]):
        a, b = old["types"].get(name, {}), new["types"][name]
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                lines.append(f"{name}.{key}: {a.get(key)!r} -> {b.get(key)!r}")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=Path, default=REFERENCE)
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = parser.parse_args()
    if not args.reference.is_file():
        print(f"no AI2-THOR reference at {args.reference}", file=sys.stderr)
        return 2
    reference = json.loads(args.reference.read_text(encoding="utf-8"))
    catalogue = json.loads(CATALOGUE.read_text(encoding="utf-8"))
    new = sync(catalogue, reference)
    diff = differences(catalogue, new)
    if args.check:
        for line in diff:
            print(line)
        print(f"{CATALOGUE.name} {'agrees with' if not diff else 'DIFFERS FROM'} AI2-THOR")
        return 1 if diff else 0
    CATALOGUE.write_text(json.dumps(new, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {CATALOGUE} ({len(diff)} field(s) changed)")
    for line in diff:
        print("  " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
