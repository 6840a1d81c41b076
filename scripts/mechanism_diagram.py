"""Draw docs/images/hazard-mechanisms.png: the household rules' hazard
mechanisms as source -> pathway -> what is harmed, with the reach chain.

    python scripts/mechanism_diagram.py

The rows are the mechanism families of knowledge/household/drafts; each
rule there states its own mechanism (the ``:mechanism`` annotation).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

OUT = Path(__file__).resolve().parents[1] / "docs" / "images" / "hazard-mechanisms.png"

# family, source of harm, pathway, what is harmed
ROWS: tuple[tuple[str, str, str, str], ...] = (
    (
        "Electricity meets water",
        "a live device\n(switched on or plugged in)",
        "immersion, a wet casing, a pour,\nstanding or running water nearby",
        "a person (shock),\nthe device",
    ),
    (
        "Ignition",
        "a flame, a lit burner, a running\nheater, a hot bulb, a hot object",
        "contact, support, containment,\nproximity (with reach)",
        "cloth, paper, wood, wax,\nfood, plastic",
    ),
    (
        "Microwave field",
        "a running microwave",
        "containment\n(in it, in a dish in it)",
        "metal and metal parts, sealed shells,\nliquid left heating, the oven itself",
    ),
    (
        "Chemicals meet",
        "bleach with ammonia, an acid\nor another cleaner",
        "one vessel, one open surface,\na vessel of unknown contents",
        "people (chlorine or\nchloramine gas)",
    ),
    (
        "Poison and germs",
        "cleaners, medicine, alcohol,\nraw meat, dirt",
        "containment, contact,\nreach",
        "food, food-contact items,\na child",
    ),
    (
        "Impact",
        "a fall, a throw,\na heavy load",
        "flight, fall, support",
        "fragile things, people,\nfloors, tipping furniture",
    ),
    (
        "Blades and shards",
        "knives, broken glass",
        "hidden contact (in storage,\nin liquid, on a floor or bed)",
        "hands, feet",
    ),
    (
        "Liquids",
        "water, coffee, wine, oil",
        "a pour, a spill,\na vessel stored or tipped",
        "electronics, paper, fabric, padding,\nwood, floors (slips), valuables, plants",
    ),
    (
        "Water and drains",
        "a running tap or shower,\nsolids that do not break up",
        "overflow, an open splash guard,\na toilet's trap",
        "floors, the rooms below",
    ),
)

COLUMNS = ("source of harm", "pathway", "what is harmed")
COLOURS = ("#f6d7c3", "#d9e6f2", "#dcefd9")


def box(ax: plt.Axes, x: float, y: float, w: float, h: float, text: str, colour: str) -> None:
    ax.add_patch(
        FancyBboxPatch(
            (x, y),
            w,
            h,
            boxstyle="round,pad=0.02,rounding_size=0.08",
            facecolor=colour,
            edgecolor="#555555",
            linewidth=0.8,
        )
    )
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=8.5)


def arrow(ax: plt.Axes, x0: float, x1: float, y: float) -> None:
    ax.add_patch(
        FancyArrowPatch((x0, y), (x1, y), arrowstyle="-|>", mutation_scale=11, color="#444444")
    )


def main() -> None:
    fig, ax = plt.subplots(figsize=(13, 11))
    ax.set_xlim(0, 13)
    ax.set_ylim(-2.6, len(ROWS) + 1.1)
    ax.axis("off")
    ax.set_title(
        "Hazards as mechanisms: a source of harm reaches something vulnerable along a pathway",
        fontsize=13,
        pad=10,
    )
    xs = (2.3, 5.7, 9.1)
    w, h = 3.0, 0.78
    top = len(ROWS)
    for i, col in enumerate(COLUMNS):
        ax.text(xs[i] + w / 2, top + 0.45, col, ha="center", fontsize=11, weight="bold")
    for r, (family, source, pathway, harmed) in enumerate(ROWS):
        y = top - 1 - r
        ax.text(2.1, y + h / 2, family, ha="right", va="center", fontsize=9.5, weight="bold")
        for i, text in enumerate((source, pathway, harmed)):
            box(ax, xs[i], y, w, h, text, COLOURS[i])
        arrow(ax, xs[0] + w + 0.05, xs[1] - 0.05, y + h / 2)
        arrow(ax, xs[1] + w + 0.05, xs[2] - 0.05, y + h / 2)
    # The reach chain, defined once (mechanisms.omn) and used by every rule.
    y = -1.9
    ax.text(
        0.2,
        -0.6,
        "Reach (defined once): what stands on or lies in a thing is near what that thing is near",
        fontsize=10,
        weight="bold",
    )
    nodes = (("Candle_1", 0.8), ("Shelf_1", 4.6), ("Curtains_1", 8.4))
    for name, x in nodes:
        box(ax, x, y, 2.2, 0.7, name, "#eeeeee")
    for (_, x0), (_, x1), label in zip(nodes, nodes[1:], ("isOn", "isNear"), strict=False):
        arrow(ax, x0 + 2.25, x1 - 0.05, y + 0.35)
        ax.text((x0 + 2.2 + x1) / 2, y + 0.5, label, ha="center", fontsize=9)
    ax.add_patch(
        FancyArrowPatch(
            (nodes[0][1] + 1.1, y - 0.02),
            (nodes[2][1] + 1.1, y - 0.02),
            connectionstyle="arc3,rad=0.25",
            arrowstyle="-|>",
            mutation_scale=11,
            color="#b03a2e",
            linestyle="--",
        )
    )
    ax.text(
        5.7, y - 0.75, "isNear (entailed: isOn o isNear)", ha="center", fontsize=9, color="#b03a2e"
    )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=110, bbox_inches="tight")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
