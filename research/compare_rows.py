"""A network's `agndc eval` rows against a reference's: the table a checkpoint is chosen by.

    .venv/bin/python research/compare_rows.py REF/rows.csv CAND/rows.csv [CAND2/rows.csv ...] \
        [--method agndc]

The reference rows hold marching cubes, ``oracle_binary`` and METHOD (the shipped network);
each candidate file holds METHOD too (another checkpoint, another stage), scored on the same
meshes, resolution and grid placements. Printed: the metric means over the placements every
file has, each row's share of the MC→``oracle_binary`` CD/EF1 headroom per class, and on how
many placements the candidate's CD is below the reference's (the noise between two frames of
one shape is often larger than a difference of means), and the mean CD difference with its
standard error, shape by shape (a shape's grids averaged first: its shifted grids are not
independent draws), so that a difference within two standard errors is read as noise.
"""

from __future__ import annotations

import argparse
import math
from collections import defaultdict
from pathlib import Path

from agndc_core.study import evaluate
from agndc_core.study.evaluate import headroom_table, markdown_table, summarize_rows


def read_rows(path) -> list[dict]:
    """The rows of an `agndc eval` rows.csv without an error, metrics as floats (nan if empty)."""
    return [row for row in evaluate.read_rows(path) if not row["error"]]


def placement(row: dict) -> tuple[str, str, str]:
    return row["name"], row["resolution"], row["shift"]


def compare(reference: list[dict], candidates: dict[str, list[dict]], method: str = "agndc"):
    """(rows, better): the reference's rows (its METHOD as "reference") and each candidate's
    METHOD rows under the candidate's label, on the placements all of them scored; and per
    label the number of placements with a CD below the reference's, of how many."""
    pick = {label: {placement(r): r for r in rows if r["method"] == method}
            for label, rows in candidates.items()}
    ours = {placement(r): r for r in reference if r["method"] == method}
    shared = set(ours).intersection(*pick.values())
    rows = []
    for row in reference:
        if placement(row) in shared:
            rows.append({**row, "method": "reference" if row["method"] == method
                         else row["method"]})
    better = {}
    for label, chosen in pick.items():  # the reference's mesh path: one shape, one count
        rows += [{**chosen[p], "method": label, "mesh": ours[p]["mesh"]} for p in sorted(shared)]
        better[label] = (sum(chosen[p]["cd"] < ours[p]["cd"] for p in shared), len(shared))
    return rows, better


def paired_cd(reference: list[dict], candidate: list[dict], method: str = "agndc"):
    """(mean, standard error, shapes) of the candidate's CD minus the reference's, METHOD's
    rows on the placements both scored: each shape's differences averaged over its grids, then
    the mean over shapes and its standard error (nan with fewer than two shapes)."""
    ours = {placement(r): r["cd"] for r in reference if r["method"] == method}
    per_shape = defaultdict(list)
    for row in candidate:
        if row["method"] == method and placement(row) in ours:
            per_shape[row["name"]].append(row["cd"] - ours[placement(row)])
    shape_means = [sum(d) / len(d) for d in per_shape.values()]
    n = len(shape_means)
    if n == 0:
        return math.nan, math.nan, 0
    mean = sum(shape_means) / n
    if n < 2:
        return mean, math.nan, n
    variance = sum((d - mean) ** 2 for d in shape_means) / (n - 1)
    return mean, math.sqrt(variance / n), n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("reference")
    parser.add_argument("candidates", nargs="+")
    parser.add_argument("--method", default="agndc")
    parser.add_argument("--labels", help="comma-separated names of the candidates (default: the "
                        "folders their rows are in)")
    args = parser.parse_args()
    labels = args.labels.split(",") if args.labels else [
        Path(path).parent.name or path for path in args.candidates]
    candidates = {}
    for label, path in zip(labels, args.candidates, strict=True):
        while label in candidates:
            label += "'"
        candidates[label] = read_rows(path)
    reference = read_rows(args.reference)
    rows, better = compare(reference, candidates, args.method)
    print(markdown_table(summarize_rows(rows)))
    print()
    print(headroom_table(rows))
    print()
    for label, (count, total) in better.items():
        mean, error, shapes = paired_cd(reference, candidates[label], args.method)
        print(f"{label}: CD below the reference's on {count} of {total} grids; CD×10⁵ "
              f"{mean * 1e5:+.3f} ± {error * 1e5:.3f} against it ({shapes} shapes, mean "
              "difference ± standard error)")


if __name__ == "__main__":
    main()
