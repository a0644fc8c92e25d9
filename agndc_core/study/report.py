"""The evaluation report (docs/results.md): every method on a folder of meshes, in the layout of the
paper's Table 1, per category, with inference times, the models used and a picture.

    agndc report ../shared/data/dev -o docs/results.md --res 64

The markdown, a CSV of every (mesh, method, resolution) row and the PNG are written next to each
other; the report names the command that produced it so it can be rebuilt.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import shlex
import sys
from pathlib import Path

import numpy as np

from ..pipeline import CHECKPOINT_NAMES, TAUBIN_ITERATIONS
from .evaluate import (
    METRIC_COLUMNS,
    check_shifts,
    evaluate_meshes,
    headroom_lines,
    markdown_table,
    method_parts,
    parse_methods,
    require_meshes,
    shift_table,
    summarize_rows,
    write_report,
)

REPORT_METHODS = ("mc", "mc_taubin", "surfacenets", "undc", "agndc", "agndc_fast",
                  "oracle_binary", "oracle", "surfacenets+bounds", "undc+bounds", "agndc+bounds")
CATEGORY_ORDER = ("CAD", "organic", "Thingi10K")
#: shapes of the picture: file stems of the evaluated folder, or names of ``SYNTHETIC_SHAPES``
#: (built here). A CAD part, a part whose flat faces are slightly off the axes, a box turned far
#: off them, an organic model and a printed part.
FIGURE_SHAPES = ("fandisk", "tilted_bracket", "rotated_box", "bunny_oded", "97171")
#: (column title, method, remesh options); method None: the ground truth, the source mesh itself
FIGURE_COLUMNS = (("marching cubes", "mc", {}), ("surface nets", "surfacenets", {}),
                  ("UNDC", "undc", {}), ("AGNDC", "agndc", {}), ("ground truth", None, {}))
#: palette colours of the written picture: the grey-blue renders lose nothing visible and the
#: file shrinks ~5x against a full-colour PNG
FIGURE_COLOURS = 48
#: the synthetic figure shapes. The rotated box is turned far off the grid axes, so its flat faces
#: and sharp edges cross voxels at every angle (marching cubes and surface nets staircase it).
#: The tilted bracket (an L of two plates with a hole through each) is turned a few degrees, as a
#: CAD part is that was modelled off the grid: its large faces cross a voxel layer only every
#: ~20 voxels, the case where learned vertices come out wavy.
ROTATED_BOX = "rotated_box"
ROTATED_BOX_EXTENTS = (1.0, 0.7, 0.5)
ROTATED_BOX_DEGREES = ((20.0, (1.0, 0.0, 0.0)), (35.0, (0.0, 1.0, 0.0)))
TILTED_BRACKET = "tilted_bracket"
TILTED_BRACKET_DEGREES = 2.5
#: the turn's axis: oblique, so that every face of the bracket is tilted
TILTED_BRACKET_AXIS = (1.0, 0.6, 0.35)


def build_report(folder, out_md, *, resolutions=(64,), methods=REPORT_METHODS,
                 n_samples=100_000, figure_shapes=FIGURE_SHAPES, ablations=None,
                 command=None, shifts: int = 0) -> Path:
    """Evaluate, then write ``out_md`` (+ ``<stem>_rows/`` and ``<stem>_shapes.png``).

    ``ablations`` maps a label to an AGNDC checkpoint path: each is evaluated like ``agndc`` at
    the first resolution and tabulated in the layout of the paper's Table 4. ``shifts`` K > 0
    adds, per resolution, the grid-alone methods on K seeded sub-voxel-shifted grids per mesh
    (``evaluate_meshes(shifts=K)``; rows in ``<stem>_rows/shifted/``).
    """
    out_md = Path(out_md)
    out_md.parent.mkdir(parents=True, exist_ok=True)
    meshes = require_meshes(folder)
    rows = []
    for resolution in resolutions:
        rows += evaluate_meshes(meshes, methods, resolution=resolution, n_samples=n_samples)
    ablation_rows = {}
    for label, checkpoint in (ablations or {}).items():
        found = evaluate_meshes(meshes, [f"{label}=agndc"], resolution=resolutions[0],
                                n_samples=n_samples, checkpoints={label: checkpoint})
        ablation_rows[label] = (Path(checkpoint), found)
    grid_alone = [m for m in methods if not method_parts(m)[2]]
    shifted = [r for resolution in (resolutions if shifts else ())
               for r in evaluate_meshes(meshes, grid_alone, resolution=resolution,
                                        n_samples=n_samples, shifts=shifts)]
    rows_dir = out_md.parent / f"{out_md.stem}_rows"
    write_report(rows + [r for _, found in ablation_rows.values() for r in found], rows_dir)
    if shifted:
        write_report(shifted, rows_dir / "shifted")
    figure = out_md.parent / f"{out_md.stem}_shapes.png"
    pictured = render_figure(meshes, figure_shapes, figure, resolution=resolutions[0],
                             colours=FIGURE_COLOURS)
    text = _markdown(rows, resolutions, methods, figure if pictured else None, rows_dir, command,
                     n_samples, ablation_rows, figure_shapes=figure_shapes, shifted=shifted)
    out_md.write_text(text)
    return out_md


def _markdown(rows, resolutions, methods, figure, rows_dir, command, n_samples,
              ablation_rows, *, figure_shapes=(), shifted=()) -> str:
    lines = ["# AGNDC results on the dev meshes", ""]
    lines += [f"Produced by `{command}` on {datetime.date.today().isoformat()}, "
              f"{platform.machine()} with {os.cpu_count()} CPU cores, numpy "
              f"{np.__version__}, Python {platform.python_version()}. Every mesh is "
              "voxelised at the stated resolution (voxels on the longest side); every method "
              "reconstructs that same binary grid, and the metrics (UNDC definitions, "
              f"{n_samples:,} samples per surface, the ground truth's normalised frame) compare "
              "the result with the original mesh. Means over shapes; ECD/EF1 skip shapes "
              "without sharp edges. `oracle` contours ground-truth labels: the ceiling of this "
              "contouring. "
              "`oracle_binary` is the oracle with what a binary grid cannot tell put back (on "
              "exactly axis-aligned faces the vertex sits mid-layer along the normal): an "
              "approximate ceiling for any method that sees only the grid. "
              "`surfacenets` (the mean of each cell's crossed-edge midpoints) and `mc_taubin` "
              f"(marching cubes + trimesh Taubin smoothing, {TAUBIN_ITERATIONS} iterations) "
              "need no weights. `agndc`, `agndc_fast` and `undc` include the flat-patch stage "
              "(each flat voxel-face patch that is not a terrace gets one depth: the mean of the "
              "network's on the shape's outermost layers, the layer's midpoint inside and on "
              "the longest side's outermost layers; the terraces of a slightly tilted plane "
              "one plane; a terrace that a step runs round, a recessed floor or a plateau "
              "the network sees flat but off its layer's middle, the midpoint too; "
              "`flatpatches.py`) and the normal filter (the contoured mesh denoised by "
              "bilateral filtering of its face normals, which keeps its creases, with fewer "
              "passes where the surface bends like fine detail and none on a surface "
              "wrinkled all over, `normalfilter.py`). Every "
              "method sees the grid alone, except the `+bounds` rows: "
              "the same method also given the mesh's bounding box, as `agndc remesh` and the "
              "Blender add-on do for mesh input (the faces that bound the shape are put on it, "
              "`flatpatches.snap_to_bounds`). That is information the grid does not hold, so the "
              "ceilings and the quality targets are about the plain rows. "
              "Times are wall seconds of `remesh_mesh` per shape (voxelise + network + contouring "
              "+ filter; "
              "the oracle's label generation is not counted); the networks run in the numpy "
              f"runtime on {_inference_threads()} threads.", ""]
    lines += ["## Models", "", _models_table(methods), ""]
    for resolution in resolutions:
        mine = [r for r in rows if r["resolution"] == resolution]
        lines += [f"## {resolution}³: all shapes", ""] + _means(summarize_rows(mine))
        for category in _categories(mine):
            part = [r for r in mine if r["category"] == category]
            lines += [f"### {resolution}³: {category}", "",
                      markdown_table(summarize_rows(part)), ""]
        lines += [f"### {resolution}³: inference time per shape", "", _time_table(mine), ""]
        lines += [f"### {resolution}³: CD×10⁵ per shape", "", _per_shape_table(mine, "cd"), ""]
    for resolution in resolutions if shifted else ():
        lines += _shifted_section([r for r in shifted if r["resolution"] == resolution],
                                  resolution)
    if ablation_rows:
        lines += [f"## Ablation ({resolutions[0]}³, all shapes; layout of the paper's Table 4)", "",
                  _ablation_table(rows, resolutions[0], ablation_rows), ""]
    ablated = [r for _, found in ablation_rows.values() for r in found]
    errors = [r for r in rows + ablated if r["error"]]
    if errors:
        lines += ["## Failures", ""] + [f"- {r['name']} {r['method']} {r['resolution']}³: "
                                        f"{r['error']}" for r in errors] + [""]
    if figure is not None:
        titles = ", ".join(title for title, _, _ in FIGURE_COLUMNS)
        caption = figure_caption(resolutions[0], figure_shapes)
        lines += ["## Picture", "", f"![{titles}]({figure.name})", "", caption, ""]
    lines += [f"Every row: `{rows_dir.name}/rows.csv` (raw metrics, faces, seconds, errors).", ""]
    return "\n".join(lines)


def _shifted_section(rows, resolution) -> list[str]:
    """The grid-alone methods on shifted grids: means, headroom, comparisons, per-shift means."""
    count = len({r["shift"] for r in rows})
    lines = [f"## {resolution}³ on {count} shifted grids per mesh", "",
             "The same methods, each mesh voxelised "
             f"{count} times with a seeded random sub-voxel shift (uniform in [−0.5, 0.5) voxel "
             "per axis, the training data's augmentation; `agndc eval --shifts`) instead of "
             "centred on its bounding box, which puts the box's faces at fixed depths in their "
             "layers. Means over meshes and shifts; below them, each shift's mean and their "
             "spread: one grid per mesh moves these means by several percent.", ""]
    return lines + _means(summarize_rows(rows)) + [shift_table(rows)]


def _means(summaries) -> list[str]:
    """The means table, its headroom lines and the AGNDC comparison sentences."""
    lines = [markdown_table(summaries), ""]
    for line in headroom_lines(summaries):
        lines += [line, ""]
    return lines + _comparison(summaries)


#: the sentences of ``_comparison``: (label, method, the baselines given the same information)
COMPARISONS = (("AGNDC", "agndc", ("mc", "surfacenets", "undc")),
               ("AGNDC+bounds", "agndc+bounds", ("surfacenets+bounds", "undc+bounds")))


def _comparison(summaries) -> list[str]:
    """Sentences: AGNDC against each baseline, metric by metric (computed, not written by hand)."""
    by_method = {s["method"]: s for s in summaries}
    lower_is_better = {"cd", "ecd"}
    out = []
    for label, method, bases in COMPARISONS:
        for base in bases:
            if method not in by_method or base not in by_method:
                continue
            parts = []
            for column in METRIC_COLUMNS:
                a, b = by_method[method][column], by_method[base][column]
                if not (math.isfinite(a) and math.isfinite(b)) or b == 0:
                    continue
                better = a < b if column in lower_is_better else a > b
                parts.append(f"{column.upper()} {100 * (a - b) / abs(b):+.1f} % "
                             f"({'better' if better else 'worse'})")
            out.append(f"{label} against {base}: " + ", ".join(parts) + ".")
    return out + [""] if out else []


def _categories(rows) -> list[str]:
    present = {r["category"] for r in rows}
    return [c for c in CATEGORY_ORDER if c in present] + sorted(present - set(CATEGORY_ORDER))


def _time_table(rows) -> str:
    """Median and max wall time of ``remesh_mesh`` (voxelise + reconstruct + contour) per method."""
    lines = ["| method | median s | max s | median faces |", "|---|---|---|---|"]
    for method in dict.fromkeys(r["method"] for r in rows):
        ok = [r for r in rows if r["method"] == method and not r["error"]]
        if not ok:
            continue
        seconds = np.array([r["seconds"] for r in ok])
        faces = np.array([r["faces"] for r in ok])
        lines.append(f"| {method} | {np.median(seconds):.2f} | {seconds.max():.2f} | "
                     f"{int(np.median(faces)):,} |")
    return "\n".join(lines)


def _per_shape_table(rows, column) -> str:
    from ..metrics import REPORT_SCALE

    methods = list(dict.fromkeys(r["method"] for r in rows))
    lines = ["| shape | category | " + " | ".join(methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for name in dict.fromkeys(r["name"] for r in rows):
        mine = {r["method"]: r for r in rows if r["name"] == name}
        first = next(iter(mine.values()))
        cells = []
        for method in methods:
            value = mine[method][column] if method in mine else math.nan
            cells.append("–" if math.isnan(value) else f"{value * REPORT_SCALE.get(column, 1):.3f}")
        lines.append(f"| {name} | {first['category']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


ABLATION_SWITCHES = (("multi-scale", lambda c: c["levels"] > 0),
                     ("LWSA", lambda c: c["use_attention"]), ("DSConv", lambda c: c["use_snake"]),
                     ("DFFM", lambda c: c["levels"] > 0 and c["use_dffm"]),
                     ("CRPM", lambda c: c["levels"] > 0 and c["use_crpm"]))


def _ablation_table(rows, resolution, ablation_rows) -> str:
    """One line per configuration (modules ticked), baseline first and full AGNDC last."""
    from ..checkpoint import default_checkpoint_path
    from ..metrics import REPORT_SCALE

    entries = []
    for method in ("undc", *ablation_rows, "agndc"):
        if method in ablation_rows:
            path, found = ablation_rows[method]
        else:
            path = default_checkpoint_path(CHECKPOINT_NAMES[method])
            found = [r for r in rows if r["method"] == method and r["resolution"] == resolution]
        if found and path.is_file():
            meta = json.loads(path.with_suffix(".json").read_text())
            entries.append((method, meta, summarize_rows(found)[0]))
    head = ["configuration"] + [n for n, _ in ABLATION_SWITCHES] + [
        "parameters", "CD×10⁵ ↓", "F1 ↑", "NC ↑", "ECD×10² ↓", "EF1 ↑"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method, meta, summary in entries:
        ticks = ["✓" if test(meta["model_config"]) else "" for _, test in ABLATION_SWITCHES]
        values = [f"{meta['parameters']:,}"]
        values += [f"{summary[c] * REPORT_SCALE.get(c, 1.0):.3f}" for c in METRIC_COLUMNS]
        lines.append("| " + " | ".join([method] + ticks + values) + " |")
    return "\n".join(lines)


def _models_table(methods) -> str:
    from ..checkpoint import default_checkpoint_path

    lines = ["| method | checkpoint | config | parameters | weights | training |",
             "|---|---|---|---|---|---|"]
    for method in methods:
        if method not in CHECKPOINT_NAMES:
            continue
        path = default_checkpoint_path(CHECKPOINT_NAMES[method])
        if not path.is_file():
            lines.append(f"| {method} | missing | | | | |")
            continue
        meta = json.loads(path.with_suffix(".json").read_text())
        config = meta["model_config"]
        switches = [k for k in ("use_attention", "use_snake", "use_dffm", "use_crpm")
                    if not config.get(k, True)]
        described = (f"ω={config['width']}, scales={config['levels'] + 1}"
                     + (f", snake kernel {config['snake_kernel']}" if config.get("use_snake")
                        else "") + (f", off: {', '.join(switches)}" if switches else ""))
        training = meta.get("training", {})
        data = training.get("data", {})
        lines.append(f"| {method} | `{path.name}` | {described} | {meta['parameters']:,} | "
                     f"{path.stat().st_size / 2 ** 20:.2f} MiB | {_steps_trained(training)}, "
                     f"{data.get('samples', '?')} shapes, "
                     f"{training.get('train_seconds', 0) / 60:.0f} min on "
                     f"{_trained_on(training)}{_lineage_total(training)} |")
    return "\n".join(lines)


def _steps_trained(training: dict) -> str:
    """"3000/300/300 steps at scales 0/1/2"; "2000 of 4000/0/0 ..." for a checkpoint taken
    during the finest scale's schedule (``--val-steps``), whose learning rate was mid-decay."""
    per_scale = training.get("steps_per_scale", [])
    steps = "/".join(str(s) for s in per_scale)
    scales = "/".join(str(s) for s in range(len(per_scale)))
    done = training.get("steps_done", {})
    if per_scale and done.get("scale") == 0 and done.get("step", per_scale[0]) < per_scale[0]:
        steps = f"{done['step']} of {steps}"
    return f"{steps} steps at scales {scales}"


def _trained_on(training: dict) -> str:
    """Where the last run's steps ran: its lineage entry's or the trainer's own record, up to the
    first comma, each machine of a resumed run once (checkpoints from before the trainer
    recorded it ran on the CPU VM)."""
    lineage = training.get("lineage") or [{}]
    last = lineage[-1] if "hardware" in lineage[-1] or "sessions" in lineage[-1] else training
    sessions = last.get("sessions") or [{"hardware": last.get("hardware") or "CPU"}]
    kinds = []  # each machine once, in the order it ran (a run resumed elsewhere: several)
    for entry in sessions:
        kind = entry["hardware"].split(",")[0]
        if kind not in kinds:
            kinds.append(kind)
    return " + ".join(kinds)


def _lineage_total(training: dict) -> str:
    lineage = training.get("lineage") or []
    if len(lineage) < 2 or "total_train_seconds" not in training:
        return ""
    return (f" (warm-started: {len(lineage)} runs, "
            f"{training['total_train_seconds'] / 60:.0f} min of steps in all)")


def _inference_threads() -> int:
    from ..runtime.parallel import get_threads

    return get_threads()


# -- picture ----------------------------------------------------------------------------------

def render_figure(meshes, names, path, *, resolution=64, columns=FIGURE_COLUMNS,
                  colours: int | None = None) -> bool:
    """A grid of renders: one row per named shape, one column per (title, method, options) of
    ``columns`` (method None: the ground truth). False if none. With ``colours``, written as a
    palette PNG of that many colours (``save_small_png``).

    ``names`` are file stems of ``meshes`` or keys of ``SYNTHETIC_SHAPES``; names found nowhere
    are skipped.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..pipeline import remesh_mesh

    chosen = _figure_shapes(meshes, names)
    if not chosen:
        return False
    n_cols = len(columns)
    fig = plt.figure(figsize=(3.6 * n_cols, 3.6 * len(chosen)), dpi=110)
    for row, (name, category, vertices, faces) in enumerate(chosen):
        for col, (title, method, options) in enumerate(columns):
            if method is None:
                pv, pf = vertices, faces
            else:
                # the grid alone, as the tables' plain method names
                result = remesh_mesh(vertices, faces, resolution=resolution, method=method,
                                     source=name, source_bounds=False, **options)
                pv, pf = result.vertices, result.faces
            ax = fig.add_subplot(len(chosen), n_cols, row * n_cols + col + 1, projection="3d")
            _draw(ax, np.asarray(pv, float), np.asarray(pf), vertices)
            title = title if row == 0 else ""
            ax.set_title(f"{title}\n{name} ({category})" if col == 0 else title)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0, hspace=0.05)
    if colours is None:
        fig.savefig(path)
    else:
        save_small_png(fig, path, colours)
    plt.close(fig)
    return True


def figure_caption(resolution: int, names) -> str:
    """The picture's caption: its columns and what the synthetic shapes among ``names`` are."""
    titles = ", ".join(title for title, _, _ in FIGURE_COLUMNS)
    caption = f"Columns: {titles} at {resolution}³, edges drawn over the shading."
    if TILTED_BRACKET in names:
        caption += (" The tilted bracket is an L of two plates with a hole through each, turned "
                    f"{TILTED_BRACKET_DEGREES:g}° about an oblique axis, so its large faces are "
                    "slightly off the grid axes.")
    if ROTATED_BOX in names:
        turns = " and ".join(f"{a:g}° about {'xyz'[int(np.argmax(v))]}"
                             for a, v in ROTATED_BOX_DEGREES)
        caption += (f" The rotated box is a {' × '.join(str(e) for e in ROTATED_BOX_EXTENTS)}"
                    f" box turned {turns}.")
    return caption


def _figure_shapes(meshes, names) -> list[tuple]:
    """(name, category, (V, 3) float vertices, (F, 3) int faces) for each name that exists."""
    from ..gridio import load_mesh

    chosen = []
    for name in names:
        if name in SYNTHETIC_SHAPES:
            chosen.append((name, "synthetic", *SYNTHETIC_SHAPES[name]()))
            continue
        for mesh_path, category in meshes:
            if Path(mesh_path).stem == name:
                chosen.append((name, category, *load_mesh(mesh_path)))
                break
    return chosen


def rotated_box():
    """The figure's ``ROTATED_BOX``: (8, 3) float64 vertices, (12, 3) int64 faces, outward."""
    import trimesh

    mesh = trimesh.creation.box(ROTATED_BOX_EXTENTS)
    for degrees, axis in ROTATED_BOX_DEGREES:
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(degrees), axis))
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def tilted_bracket():
    """The figure's ``TILTED_BRACKET``: (V, 3) float64 vertices, (F, 3) int64 faces, outward.

    A base plate 1.0 x 0.6 x 0.14 and an upright plate 0.14 x 0.6 x 0.5 on its end, each with a
    round hole through it, turned ``TILTED_BRACKET_DEGREES`` about ``TILTED_BRACKET_AXIS``.
    """
    import trimesh
    from manifold3d import Manifold

    base = Manifold.cube((1.0, 0.6, 0.14))
    upright = Manifold.cube((0.14, 0.6, 0.5)).translate((0.0, 0.0, 0.14))
    base_hole = Manifold.cylinder(0.4, 0.1, 0.1, 64).translate((0.6, 0.3, -0.1))
    upright_hole = (Manifold.cylinder(0.4, 0.09, 0.09, 64)
                    .rotate((0.0, 90.0, 0.0)).translate((-0.1, 0.3, 0.42)))
    part = (base + upright) - base_hole - upright_hole
    part = part.translate((-0.5, -0.3, -0.32))
    mesh = part.to_mesh()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    turn = trimesh.transformations.rotation_matrix(np.radians(TILTED_BRACKET_DEGREES),
                                                   TILTED_BRACKET_AXIS)
    vertices = vertices @ turn[:3, :3].T
    return vertices, np.asarray(mesh.tri_verts, dtype=np.int64)


#: the figure's synthetic shapes by name: a function returning (vertices, faces)
SYNTHETIC_SHAPES = {ROTATED_BOX: rotated_box, TILTED_BRACKET: tilted_bracket}


def voxel_faces(grid):
    """Boundary quads of the occupied voxels (as triangles, facing out of the voxels) in world
    coordinates: a closed, outward surface, the voxel model itself."""
    occ = np.pad(grid.occupancy, 1)
    corners = []
    for axis in range(3):
        change = np.diff(occ.astype(np.int8), axis=axis)  # +1: empty->full along +axis
        idx = np.argwhere(change != 0)
        base = idx.astype(float) - 1.0  # back to unpadded voxel indices (lower voxel)
        base[:, axis] += 0.5  # the face between the two voxels
        u, v = [a for a in range(3) if a != axis]
        quad = np.zeros((len(idx), 4, 3))
        for n, (du, dv) in enumerate(((-.5, -.5), (.5, -.5), (.5, .5), (-.5, .5))):
            quad[:, n] = base
            quad[:, n, u] += du
            quad[:, n, v] += dv
        # the corners' order turns the quad's normal to e_u x e_v: +x, -y, +z for axes 0, 1,
        # 2; a face out of the voxels points down the axis where the voxels begin (+1)
        outward = -change[tuple(idx.T)] * (-1 if axis == 1 else 1)
        quad[outward < 0] = quad[outward < 0, ::-1]
        corners.append(quad)
    quads = np.concatenate(corners)
    verts = grid.index_to_world(quads.reshape(-1, 3))
    q = np.arange(len(quads))[:, None] * 4
    tris = np.concatenate([q + [0, 1, 2], q + [0, 2, 3]])
    return verts, tris


def _draw(ax, vertices, faces, reference):
    """Flat-shaded triangles with their edges drawn thin (the wireframe shows the tessellation),
    head-light style, framed on the reference mesh's bounds."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    shade = 0.25 + 0.75 * np.abs(normal @ light)  # two-sided: orientation does not matter here
    colors = np.clip(shade[:, None] * np.array([0.75, 0.8, 0.9]), 0, 1)
    # thinner lines for denser meshes, so a 64³ reconstruction is not drowned in black
    width = float(np.clip(12.0 / np.sqrt(max(len(faces), 1)), 0.04, 0.6))
    ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors=(0.1, 0.1, 0.2, 0.4),
                                         linewidths=width))
    frame_axes(ax, reference.min(0), reference.max(0))


def frame_axes(ax, lo, hi, *, zoom: float = 0.42, elev: float = 25, azim: float = -60) -> None:
    """A 3-D axes framed on the box ``lo``..``hi`` (equal scales, no axes drawn); a ``zoom``
    under 1/2 of the box's longest side leaves the box's corners empty."""
    centre, half = (np.asarray(lo) + hi) / 2, (np.asarray(hi) - lo).max() * zoom
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def save_small_png(fig, path: Path, colours: int = 256) -> None:
    """The figure as a palette PNG (a few shades per colour suffice): about a third the bytes."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    buffer.seek(0)
    image = Image.open(buffer).convert("RGB")
    # octree keeps the few orange faces their own colours (median cut merges them into grey)
    image.quantize(colours, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)


def add_parser(sub) -> None:
    p = sub.add_parser("report", help="evaluate all methods on a mesh folder; write results.md")
    p.add_argument("folder", type=Path)
    p.add_argument("-o", "--out", type=Path, default=Path("docs/results.md"))
    p.add_argument("--res", type=int, nargs="+", default=[64])
    p.add_argument("--methods", default=",".join(REPORT_METHODS))
    p.add_argument("--samples", type=int, default=100_000)
    p.add_argument("--ablation", action="append", default=[], metavar="LABEL=CHECKPOINT",
                   help="an AGNDC variant's checkpoint for the ablation table (repeatable)")
    p.add_argument("--shifts", type=int, default=0, metavar="K",
                   help="also score the grid-alone methods on K seeded sub-voxel-shifted grids "
                   "per mesh, at every resolution (agndc eval --shifts)")
    p.set_defaults(func=_cmd_report)


def _cmd_report(args) -> int:
    from ..errors import AGNDCError

    methods = parse_methods(args.methods)
    ablations = {}
    for item in args.ablation:
        label, sep, checkpoint = item.partition("=")
        if not sep or not label or not Path(checkpoint).is_file():
            raise AGNDCError(f"--ablation {item!r}: expected LABEL=CHECKPOINT (an existing "
                             ".safetensors file)")
        ablations[label] = checkpoint
    command = "agndc " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    check_shifts(args.shifts)  # before the long centred evaluation
    out = build_report(args.folder, args.out, resolutions=args.res, methods=methods,
                       n_samples=args.samples, ablations=ablations, command=command,
                       shifts=args.shifts)
    print(f"written: {out}")
    return 0
