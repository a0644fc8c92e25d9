"""Evaluate reconstruction methods on a folder of meshes: one row per (mesh, method), as in UNDC.

Every mesh is voxelised at the chosen resolution; each method reconstructs that same grid, and
the metrics compare the result with the original mesh in the original mesh's normalised frame.

A method sees the grid alone, as the paper's setting asks. ``<method>+bounds`` (for the
``pipeline.BOUNDED_METHODS``) is the same method given the mesh's bounding box as well, as
``remesh`` does by default for mesh input (``flatpatches.snap_to_bounds``): it is what a user
remeshing a mesh gets, but information the grid does not hold, so it is tabulated apart.
"""

from __future__ import annotations

import csv
import math
import re
import time
from pathlib import Path

import numpy as np

from ..errors import AGNDCError
from ..pipeline import remesh_mesh

METRIC_COLUMNS = ("cd", "f1", "nc", "ecd", "ef1")
HEADERS = {"cd": "CD×10⁵ ↓", "f1": "F1 ↑", "nc": "NC ↑", "ecd": "ECD×10² ↓", "ef1": "EF1 ↑"}
#: metrics of the "share of the MC→oracle headroom" line (``headroom_shares``)
HEADROOM_COLUMNS = ("cd", "ef1")
#: the ceilings the headroom lines measure against (``headroom_lines``)
HEADROOM_CEILINGS = ("oracle", "oracle_binary")
#: a method name with this suffix is evaluated with the mesh's bounding box (module docstring)
BOUNDS_SUFFIX = "+bounds"
#: MANIFEST.csv "kind" -> report category
CATEGORIES = {"cad": "CAD", "organic": "organic", "print (Thingi10K)": "Thingi10K",
              "print": "printed"}  # the last: the generated validation family (validation.py)


def find_meshes(folder: Path) -> list[tuple[Path, str]]:
    """Meshes under ``folder`` with their category, from MANIFEST.csv when there is one."""
    from ..gridio import is_mesh_path

    folder = Path(folder)
    if folder.is_file():
        return [(folder, "mesh")]
    manifest = folder / "MANIFEST.csv"
    if manifest.exists():
        with open(manifest, newline="") as handle:
            rows = list(csv.DictReader(handle))
        found = [(folder / r["file"], CATEGORIES.get(r.get("kind", ""), r.get("kind", "other")))
                 for r in rows if is_mesh_path(r["file"])]
        return [(path, kind) for path, kind in found if path.exists()]
    return [(p, "mesh") for p in sorted(folder.rglob("*")) if p.is_file() and is_mesh_path(p)]


def parse_methods(text: str) -> list[str]:
    """``"mc,agndc+bounds,cpu3=agndc"`` -> ["mc", "agndc+bounds", "cpu3=agndc"]; unknown names
    raise one clear error. ``LABEL=METHOD`` evaluates METHOD under its own label (a second
    network of the same method, with ``checkpoints[LABEL]``; ``method_parts``)."""
    from ..pipeline import BOUNDED_METHODS, METHODS

    methods = [m.strip() for m in text.split(",") if m.strip()]
    parts = [method_parts(name) for name in methods]
    unknown = [name for name, (label, base, bounded) in zip(methods, parts)
               if not label or base not in (BOUNDED_METHODS if bounded else METHODS)]
    if unknown:
        raise AGNDCError(f"unknown method(s) {unknown}; choose from {', '.join(METHODS)}, or "
                         + ", ".join(m + BOUNDS_SUFFIX for m in BOUNDED_METHODS)
                         + ", each optionally as LABEL=METHOD")
    labels = [label for label, _, _ in parts]
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        raise AGNDCError(f"method label(s) {repeated} given twice; name them apart with "
                         "LABEL=METHOD")
    return methods


def split_method(name: str) -> tuple[str, bool]:
    """``"agndc+bounds"`` -> ("agndc", True): the method and whether it gets the source bounds."""
    if name.endswith(BOUNDS_SUFFIX):
        return name[:-len(BOUNDS_SUFFIX)], True
    return name, False


def method_parts(name: str) -> tuple[str, str, bool]:
    """A method entry -> (label of its rows, method, with source bounds):
    ``"agndc+bounds"`` -> ("agndc+bounds", "agndc", True); ``"cpu3=agndc"`` -> ("cpu3",
    "agndc", False)."""
    label, sep, method = name.partition("=")
    base, bounded = split_method(method.strip() if sep else name)
    return label.strip(), base, bounded


def grid_shifts(mesh_index: int, count: int) -> np.ndarray:
    """(count, 3) sub-voxel shifts of one mesh's evaluation grids, uniform in [-0.5, 0.5) voxel
    per axis (the training data's augmentation), seeded by the mesh's index so that every
    method and every run sees the same grids; the first row does not depend on ``count``."""
    return np.random.default_rng([mesh_index, 77]).uniform(-0.5, 0.5, (count, 3))


def check_shifts(shifts: int) -> int:
    """``shifts`` of ``evaluate_meshes`` (0: the centred grid), refused when negative."""
    if shifts < 0:
        raise AGNDCError(f"--shifts must be 0 or more, got {shifts}")
    return shifts


def method_checkpoint(checkpoints: dict, label: str, method: str):
    """The weights of a method entry: its label's own checkpoint, else its method's, else None
    (the shipped weights)."""
    return checkpoints.get(label, checkpoints.get(method))


def grid_placements(mesh_index: int, shifts: int) -> list[tuple]:
    """(shift column, sub-voxel shift) of every grid a mesh is scored on."""
    if not shifts:
        return [(None, (0.0, 0.0, 0.0))]  # the centred grid
    return list(enumerate(grid_shifts(mesh_index, shifts)))


def require_meshes(folder, limit: int | None = None) -> list[tuple[Path, str]]:
    """``find_meshes`` (the first ``limit``), refusing a folder without any."""
    meshes = find_meshes(folder)[:limit]
    if not meshes:
        raise AGNDCError(f"{folder}: no meshes found")
    return meshes


def evaluate_meshes(meshes, methods, *, resolution=64, n_samples=100_000, checkpoints=None,
                    shifts: int = 0, progress=True, normal_filter: bool = True) -> list[dict]:
    """Rows of metrics (raw, not scaled) for every mesh and method; failures become error rows.

    Args:
        methods: entries of ``parse_methods``; a row's "method" is the entry's label.
        checkpoints: {label or method: checkpoint path} for the learned methods (a label's own
            entry first, then its method's; otherwise the shipped weights).
        shifts: 0 scores each mesh on ``voxelize``'s centred grid. K > 0 scores it on K grids
            moved by ``grid_shifts`` instead (row column "shift" = 0..K-1): the centred grid
            puts the faces of the mesh's bounding box at fixed depths in their voxel layers,
            a cue real voxel data do not carry, and one grid per mesh leaves the means at the
            mercy of each mesh's phase (docs/experiments/shifted-grid-evaluation.md).
        normal_filter: False scores the learned methods' meshes as contoured, without the
            bilateral normal filter (``pipeline.remesh``).
    """
    from tqdm import tqdm

    from ..gridio import load_mesh
    from ..metrics import evaluate

    checkpoints = checkpoints or {}
    check_shifts(shifts)
    rows = []
    jobs = [(path, kind, k, shift, method) for index, (path, kind) in enumerate(meshes)
            for k, shift in grid_placements(index, shifts) for method in methods]
    bar = tqdm(jobs, desc="eval", unit="run", disable=not progress)
    cache = {}
    for path, kind, k, shift, method in bar:
        label, base, bounded = method_parts(method)
        bar.set_postfix_str(f"{Path(path).name} {label}" + ("" if k is None else f" shift {k}"))
        row = {"mesh": str(path), "name": Path(path).stem, "category": kind, "method": label,
               "resolution": resolution, "shift": k}
        try:
            if path not in cache:
                cache = {path: load_mesh(path)}
            vertices, faces = cache[path]
            result = remesh_mesh(vertices, faces, resolution=resolution, method=base,
                                 checkpoint=method_checkpoint(checkpoints, label, base),
                                 source=Path(path).name, source_bounds=bounded, shift=shift,
                                 normal_filter=normal_filter)
            start = time.perf_counter()
            metrics = evaluate(result.vertices, result.faces, vertices, faces, n_samples=n_samples)
            row.update({column: metrics[column] for column in METRIC_COLUMNS})
            row.update(faces=len(result.faces), seconds=result.seconds,
                       metric_seconds=time.perf_counter() - start, error="")
        except AGNDCError as exc:
            row.update({k: math.nan for k in METRIC_COLUMNS}, faces=0, seconds=math.nan,
                       error=str(exc))
        rows.append(row)
    return rows


def summarize_rows(rows, by=("method",)) -> list[dict]:
    """Nan-aware means of the metrics per group (ECD/EF1 skip shapes without GT edges)."""
    groups: dict[tuple, list] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in by), []).append(row)
    out = []
    for key, members in groups.items():
        summary = dict(zip(by, key))
        # a mesh scored on several shifted grids counts once; a row without a name on its own
        summary["shapes"] = len({m.get("name", i) for i, m in enumerate(members)})
        for column in METRIC_COLUMNS + ("seconds",):
            values = np.array([m[column] for m in members], dtype=float)
            values = values[np.isfinite(values)]
            summary[column] = float(values.mean()) if values.size else math.nan
        out.append(summary)
    return out


def markdown_table(summaries, first="method") -> str:
    """Paper-style table: CD×10⁵, F1, NC, ECD×10², EF1 (and seconds)."""
    from ..metrics import REPORT_SCALE

    head = [first, "shapes"] + [HEADERS[c] for c in METRIC_COLUMNS] + ["time s"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in summaries:
        cells = [str(s[first]), str(s["shapes"])]
        for column in METRIC_COLUMNS:
            value = s[column] * REPORT_SCALE.get(column, 1.0)
            cells.append("–" if math.isnan(value) else f"{value:.3f}")
        cells.append("–" if math.isnan(s["seconds"]) else f"{s['seconds']:.2f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def shift_table(rows, columns=HEADROOM_COLUMNS) -> str:
    """Markdown: each method's mean per shift (``evaluate_meshes(shifts=K)``) for ``columns``,
    and the standard deviation of those means: how far one grid placement moves a mean, the
    noise a difference between methods has to exceed."""
    from ..metrics import REPORT_SCALE

    shifts = sorted({r["shift"] for r in rows if r["shift"] is not None})
    summaries = summarize_rows([r for r in rows if r["shift"] is not None], by=("method", "shift"))
    means = {(s["method"], s["shift"]): s for s in summaries}
    methods = list(dict.fromkeys(s["method"] for s in summaries))
    lines = []
    for column in columns:
        scale = REPORT_SCALE.get(column, 1.0)
        head = ([f"{HEADERS[column]} by shift"] + [f"shift {k}" for k in shifts]
                + ["std of the shift means"])
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for method in methods:
            values = np.array([means[method, k][column] * scale for k in shifts])
            spread = float(np.std(values, ddof=1)) if len(values) > 1 else math.nan
            cells = [method] + [f"{v:.3f}" for v in values] + [f"{spread:.3f}"]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def headroom_shares(summaries, columns=HEADROOM_COLUMNS,
                    ceiling: str = "oracle") -> dict[str, dict[str, float]]:
    """Each method's share of the gap between marching cubes and ``ceiling``, in percent.

    For a lower-is-better metric (CD) the share is ``(m_mc - m) / (m_mc - m_oracle)``, for a
    higher-is-better one (EF1) ``(m - m_mc) / (m_oracle - m_mc)``: 0 % is marching cubes, 100 %
    the ceiling method ("oracle", or "oracle_binary": what binary input can reach), and a
    negative share is worse than marching cubes. Computed from the means in ``summaries``
    (``summarize_rows``); empty when mc or the ceiling is missing, NaN where the gap is zero or
    a mean is missing.

    Returns:
        {method: {column: percent}} for every summarised method, in the summaries' order.
    """
    by_method = {s["method"]: s for s in summaries}
    if "mc" not in by_method or ceiling not in by_method:
        return {}
    shares = {}
    for method, summary in by_method.items():
        shares[method] = {}
        for column in columns:
            base, top, value = (by_method["mc"][column], by_method[ceiling][column],
                                summary[column])
            gap = top - base  # the sign cancels: (value - base) / gap for either direction
            ok = all(math.isfinite(v) for v in (base, top, value)) and gap != 0
            # + 0.0: mc's own share is 0 / negative gap = -0.0, shown as "0.0"
            shares[method][column] = 100.0 * (value - base) / gap + 0.0 if ok else math.nan
    return shares


def headroom_line(summaries, columns=HEADROOM_COLUMNS, ceiling: str = "oracle") -> str:
    """One markdown line: "Share of the MC→ceiling headroom ..." per metric; "" without mc or
    the ceiling."""
    shares = headroom_shares(summaries, columns, ceiling)
    if not shares:
        return ""
    parts = []
    for column in columns:
        cells = [f"{method} {'–' if math.isnan(s[column]) else f'{s[column]:.1f} %'}"
                 for method, s in shares.items()]
        parts.append(f"{column.upper()}: " + ", ".join(cells))
    return (f"Share of the MC→{ceiling} headroom (0 % = mc, 100 % = {ceiling}, from the means "
            f"above; (mc − method) / (mc − {ceiling}) for CD, "
            f"(method − mc) / ({ceiling} − mc) for EF1): " + "; ".join(parts) + ".")


def headroom_lines(summaries, columns=HEADROOM_COLUMNS) -> list[str]:
    """The headroom line against each ceiling that was evaluated: the oracle (this
    contouring's ceiling) and oracle_binary (approximately what binary input can reach)."""
    lines = [headroom_line(summaries, columns, ceiling) for ceiling in HEADROOM_CEILINGS]
    return [line for line in lines if line]


def headroom_table(rows, ceiling: str = "oracle_binary", columns=HEADROOM_COLUMNS) -> str:
    """A markdown table of each method's share of the MC→``ceiling`` headroom per category and
    over all meshes (cells "CD % / EF1 %", ``headroom_shares`` of each group's means); "" when
    mc or the ceiling was not evaluated."""
    categories = list(dict.fromkeys(r["category"] for r in rows))
    groups = [(c, [r for r in rows if r["category"] == c]) for c in categories]
    groups.append(("all", rows))
    shares = {name: headroom_shares(summarize_rows(group), columns, ceiling)
              for name, group in groups}
    if not shares["all"]:
        return ""

    def cell(share: dict) -> str:
        return " / ".join("–" if math.isnan(share[c]) else f"{share[c]:.1f} %" for c in columns)

    names = [name for name, _ in groups]
    counts = {name: len({r["mesh"] for r in group}) for name, group in groups}
    lines = [f"Share of the MC→{ceiling} headroom ({' / '.join(c.upper() for c in columns)})",
             "", "| method | " + " | ".join(f"{n} ({counts[n]})" for n in names) + " |",
             "|---" * (len(names) + 1) + "|"]
    for method in shares["all"]:
        lines.append(f"| {method} | " + " | ".join(
            cell(shares[n][method]) if method in shares[n] else "–" for n in names) + " |")
    return "\n".join(lines)


def read_rows(path) -> list[dict]:
    """The rows of a ``rows.csv`` that ``write_report`` wrote, the metrics and seconds as floats
    (nan where empty), the other columns as text."""
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        for column in METRIC_COLUMNS + ("seconds",):
            row[column] = float(row[column]) if row[column] not in ("", None) else math.nan
    return rows


def write_report(rows, out_dir: Path) -> dict[str, Path]:
    """Write rows.csv plus one markdown table per method (per category and overall)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = {"csv": out_dir / "rows.csv"}
    with open(written["csv"], "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0].keys()))
        writer.writeheader()
        writer.writerows(rows)
    methods = sorted({r["method"] for r in rows}, key=[r["method"] for r in rows].index)
    for method in methods:
        mine = [r for r in rows if r["method"] == method]
        text = f"# {method} at {mine[0]['resolution']}³\n\n"
        text += markdown_table(summarize_rows(mine, by=("category",)), first="category") + "\n\n"
        text += markdown_table(summarize_rows(mine)) + "\n"
        errors = [r for r in mine if r["error"]]
        if errors:
            text += "\nFailures:\n" + "".join(f"- {r['name']}: {r['error']}\n" for r in errors)
        # labels are free text (e.g. "w/o GDFEM"): keep file names to safe characters
        written[method] = out_dir / (re.sub(r"[^\w.-]+", "_", method).strip("_") + ".md")
        written[method].write_text(text)
    table = headroom_table(rows)
    if table:
        written["headroom"] = out_dir / "headroom.md"
        written["headroom"].write_text(table + "\n")
    return written
