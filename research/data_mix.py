"""What a training mix is made of: the share of each kind of sample in `agndc train-data`
folders, read from the recipes the samples carry (a Markdown table).

    .venv/bin/python research/data_mix.py DATA DATA_sheets DATA_wrinkled DATA_tilted DATA_spikes \
        DATA_layered DATA_struts DATA_rounds

Kinds: the shape family (``shapes.FAMILIES``, ``sheet``, ``layered``, ``struts`` or ``round``),
the placement (on the grid axes, turned 1-15° off them by ``--tilted``, or turned by the
generator: freely, or for a sheet, a layered part, a strut frame or a round part 1-10° for two
thirds of those), whether the surface is wrinkled and whether the shape grew spikes
(``--spikes``). A trainer given several folders draws every sample alike, so the last row (all
folders) is the mix a run sees.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

from agndc_core.study.shapes import FAMILIES


def recipes(folder) -> list[dict]:
    """The recipes of a folder's samples (only the recipe is read from each file)."""
    out = []
    for path in sorted(Path(folder).glob("sample_*.npz")):
        with np.load(path) as sample:
            out.append(json.loads(str(sample["recipe"])))
    return out


def placement(recipe: dict) -> str:
    if "tilt_degrees" in recipe:
        return "tilted"
    return "aligned" if recipe["axis_aligned"] else "turned"


def kinds(rows: list[dict]) -> dict[str, float]:
    """Shares (0..1) of each kind among ``rows``."""
    n = len(rows)
    family = Counter(r["family"] for r in rows)
    place = Counter(placement(r) for r in rows)
    shares = {f: family[f] / n for f in (*FAMILIES, "sheet", "layered", "struts", "round")}
    shares.update({p: place[p] / n for p in ("aligned", "tilted", "turned")})
    shares["wrinkled"] = sum("wrinkles" in r for r in rows) / n
    shares["spiky"] = sum(bool(r.get("spikes")) for r in rows) / n
    return shares


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", nargs="+")
    args = parser.parse_args()
    table = [(Path(f).name, recipes(f)) for f in args.folders]
    table.append(("all", [r for _, rows in table for r in rows]))
    columns = list(kinds(table[0][1]))
    print("| folder | samples | " + " | ".join(columns) + " |")
    print("|---|---|" + "---|" * len(columns))
    for name, rows in table:
        shares = kinds(rows)
        print(f"| {name} | {len(rows)} | " + " | ".join(f"{100 * shares[c]:.0f} %"
                                                      for c in columns) + " |")


if __name__ == "__main__":
    main()
