"""The learning-curve table of ``research/learning_curve.sh``: dev-mesh means per run and step.

    python research/learning_curve_table.py RUNS [--reference docs/results_rows/rows.csv]

Reads RUNS/eval_<run>_step-NNNNNN/rows.csv (64^3, grid alone) and prints one markdown row per
(run, step) beside the reference methods of the same resolution from the reference rows
(marching cubes, surface nets, MC + Taubin, the oracles, the shipped networks), a table per
mesh category, and the share of the MC→oracle headroom of CD and EF1. Step 0 of every run is
surface nets: the runs start from zero vertex heads on the surface nets prior. A run warm-started
(``--init``) from another run's checkpoint in RUNS counts its steps on from that checkpoint's, so
a continued run's points lie on the same axis as the run it continues.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

from agndc_core.metrics import REPORT_SCALE
from agndc_core.study import evaluate
from agndc_core.study.evaluate import (
    HEADROOM_COLUMNS,
    headroom_shares,
    markdown_table,
    summarize_rows,
)

REFERENCE_METHODS = ("mc", "mc_taubin", "surfacenets", "oracle_binary", "oracle")
#: the shipped networks, the end of long warm-started lineages, for scale
SHIPPED_METHODS = ("undc", "agndc")


def read_rows(path: Path, resolution: str = "64") -> list[dict]:
    return [row for row in evaluate.read_rows(path) if row["resolution"] == resolution]


def steps_before(runs: Path, run: str) -> int:
    """Finest-scale steps behind the start of ``run``: those of the checkpoint it was
    warm-started from when that checkpoint is another run's in ``runs`` (followed back), else 0.
    A scoring tag (``<run>_unfiltered``) names the same run."""
    folder = runs / run
    if not (folder / "run.json").exists() and run.endswith("_unfiltered"):
        folder = runs / run.removesuffix("_unfiltered")
    info = folder / "run.json"
    init = json.loads(info.read_text())["config"].get("init") if info.exists() else None
    if not init or Path(init).parent.resolve().parent != runs.resolve():
        return 0
    parent = Path(init).parent.name
    match = re.fullmatch(r"step-(\d+)\.safetensors", Path(init).name)
    if match:
        done = int(match.group(1))
    else:  # final.safetensors: the whole finest-scale schedule
        done = json.loads((runs / parent / "run.json").read_text())["config"]["steps"][0]
    return done + steps_before(runs, parent)


def category_table(rows: list[dict]) -> str:
    """CD×10⁵ and EF1 per mesh category and method: where a mean's change comes from."""
    summaries = summarize_rows(rows, by=("method", "category"))
    categories = sorted({s["category"] for s in summaries})
    cell = {(s["method"], s["category"]): s for s in summaries}
    methods = list(dict.fromkeys(s["method"] for s in summaries))
    head = ["method"] + [f"{c} CD×10⁵ / EF1" for c in categories]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for m in methods:
        cells = [f"{cell[m, c]['cd'] * REPORT_SCALE['cd']:.3f} / {cell[m, c]['ef1']:.3f}"
                 for c in categories]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path)
    parser.add_argument("--reference", type=Path, default=Path("docs/results_rows/rows.csv"))
    args = parser.parse_args()

    rows = [r for r in read_rows(args.reference)
            if r["method"] in REFERENCE_METHODS + SHIPPED_METHODS]
    for r in rows:
        if r["method"] in SHIPPED_METHODS:
            r["method"] += " (shipped)"
    names = {r["name"] for r in rows}
    for folder in sorted(args.runs.glob("eval_*_step-*")):
        match = re.fullmatch(r"eval_(.+)_step-(\d+)", folder.name)
        if not (match and (folder / "rows.csv").exists()):
            continue
        run = match.group(1)
        step = int(match.group(2)) + steps_before(args.runs, run)
        curve = read_rows(folder / "rows.csv")
        missing = names - {r["name"] for r in curve}
        if missing:  # a mean over other meshes would not compare
            raise SystemExit(f"{folder}: no rows for {sorted(missing)}")
        for r in curve:
            r["method"] = f"{run} @ {step}"
        rows += curve
    summaries = summarize_rows(rows)
    print(markdown_table(summaries))
    print()
    print(category_table(rows))
    print()
    shares = headroom_shares(summaries)
    print("| method | " + " | ".join(f"{c.upper()} headroom" for c in HEADROOM_COLUMNS) + " |")
    print("|---|" + "---|" * len(HEADROOM_COLUMNS))
    for method, share in shares.items():
        cells = [f"{round(share[c])} %" if math.isfinite(share[c]) else "–"
                 for c in HEADROOM_COLUMNS]
        print(f"| {method} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
