"""Thin round parts: cylinders a few voxels in radius, remeshed on randomly shifted grids.

    .venv/bin/python research/round_pins.py [--radii 3.5,5,6,7.4,11.8] [--tilt 0] [--shifts 8]
    .venv/bin/python research/round_pins.py --radii 5 --stages

A cylinder of height 1 (the longest side: 62 voxels at 64³ inside the voxeliser's margin) and
each radius in voxels, its axis along z or tilted by ``--tilt`` degrees, voxelised on
``--shifts`` random sub-voxel shifts (seeded) and remeshed from its grid alone by marching cubes,
UNDC and AGNDC. Printed per radius: the mean CD×10⁵ of each and on how many shifts AGNDC beats
UNDC. ``--stages`` adds AGNDC and UNDC without the flat patches (and with them the terraced planes
and stepped floors), AGNDC without the normal filter and AGNDC without the terraced planes.
``--round-strips WIDTH,SHARE`` runs with ``research/round_strips.py``'s rule,
``--quadratic-strips CELLS,BEND,SHARE`` with its ``--quadratic`` rule.
``--also LABEL=METHOD[:PATH]`` scores another method beside them (another network's weights
with PATH). ``--figure PNG`` draws instead the first radius's cylinder on the grid shifted by
``--shift``, by AGNDC without and with the terraced planes' round test (``flatpatches._round``),
flat-shaded: its top fifth, seen from above at a slant (the cap's outline and the side).
docs/experiments/flat-patches.md ("Known loss: thin round parts along an axis") has the
measurements.
"""

from __future__ import annotations

import argparse

import numpy as np


def cylinder(radius_voxels: float, tilt_degrees: float, voxels: int = 62):
    """(vertices, faces) of a closed cylinder of height 1, ``radius_voxels`` / ``voxels`` in
    radius, its axis turned by ``tilt_degrees`` about a fixed oblique axis."""
    import trimesh

    mesh = trimesh.creation.cylinder(radius=radius_voxels / voxels, height=1.0, sections=256)
    if tilt_degrees:
        mesh.apply_transform(trimesh.transformations.rotation_matrix(
            np.radians(tilt_degrees), [1.0, 0.3, 0.0]))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def figure(radius: float, tilt: float, shift: tuple, out: str) -> None:
    """Draw the cylinder remeshed by AGNDC without and with the round test, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agndc_core.pipeline import remesh_mesh
    from agndc_core.study.report import _draw, save_small_png
    from agndc_core.tolerances import tol

    vertices, faces = cylinder(radius, tilt)
    fig = plt.figure(figsize=(8.0, 4.2), dpi=90)
    share = tol.terrace_round_share
    for col, (title, round_share) in enumerate((("AGNDC, no round test", 2.0),
                                                ("AGNDC with the round test", share))):
        tol.terrace_round_share = round_share  # above 1 no surface is round
        out_mesh = remesh_mesh(vertices, faces, resolution=64, source_bounds=False, shift=shift)
        tol.terrace_round_share = share
        # the top fifth of the cylinder, from above at a slant: the cap's outline and the side
        top = vertices[:, 2].max() - 0.2
        kept = out_mesh.faces[(out_mesh.vertices[out_mesh.faces][..., 2] > top).all(1)]
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        _draw(ax, out_mesh.vertices, kept, vertices[vertices[:, 2] > top])
        ax.view_init(elev=50, azim=-60)
        ax.set_title(title, fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    save_small_png(fig, out)
    print(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--radii", default="3.5,5,6,7.4,11.8")
    parser.add_argument("--tilt", type=float, default=0.0)
    parser.add_argument("--shifts", type=int, default=8)
    parser.add_argument("--samples", type=int, default=30000)
    parser.add_argument("--stages", action="store_true")
    parser.add_argument("--round-strips", default="", metavar="WIDTH,SHARE",
                        help="research/round_strips.py's rule in the flat-patch stage")
    parser.add_argument("--quadratic-strips", default="", metavar="CELLS,BEND,SHARE",
                        help="research/round_strips.py --quadratic's rule in the flat-patch stage")
    parser.add_argument("--also", action="append", default=[], metavar="LABEL=METHOD[:PATH]",
                        help="score another method too, with a checkpoint of its own if PATH "
                        "is given (repeatable), e.g. fast=agndc_fast or s23=agndc_fast:run.st")
    parser.add_argument("--figure", default="", metavar="PNG")
    parser.add_argument("--shift", default="-0.21,-0.45,-0.12", metavar="X,Y,Z",
                        help="the grid's shift for --figure, voxels")
    args = parser.parse_args()
    if args.figure:
        figure(float(args.radii.split(",")[0]), args.tilt,
               tuple(float(x) for x in args.shift.split(",")), args.figure)
        return
    if args.round_strips:
        from round_strips import enable

        width, share = args.round_strips.split(",")
        enable(int(width), float(share))
    if args.quadratic_strips:
        from round_strips import enable_quadratic

        cells, bend, share = args.quadratic_strips.split(",")
        enable_quadratic(int(cells), float(bend), float(share))

    from agndc_core import pipeline
    from agndc_core.metrics import evaluate
    from agndc_core.pipeline import remesh_mesh

    variants = {"mc": {"method": "mc"}, "undc": {"method": "undc"},
                "agndc": {"method": "agndc"}}
    if args.stages:
        variants.update({
            "undc, no flat patches": {"method": "undc", "flat_patches": False},
            "agndc, no flat patches": {"method": "agndc", "flat_patches": False},
            "agndc, no normal filter": {"method": "agndc", "normal_filter": False},
            "agndc, no terraced planes": {"method": "agndc", "terraced_planes": False}})
    for spec in args.also:
        label, _, method = spec.partition("=")
        method, _, path = method.partition(":")
        variants[label] = {"method": method, "checkpoint": path or None}
    rng = np.random.default_rng(5)
    shifts = [tuple(rng.uniform(-0.5, 0.5, 3)) for _ in range(args.shifts)]
    for radius in (float(r) for r in args.radii.split(",")):
        vertices, faces = cylinder(radius, args.tilt)
        cds = {name: [] for name in variants}
        for shift in shifts:
            for name, options in variants.items():
                options = dict(options)
                # the terraced-planes stage has no option of its own: the pipeline's switch
                pipeline.TERRACED_PLANES = options.pop("terraced_planes", True)
                out = remesh_mesh(vertices, faces, resolution=64, source_bounds=False,
                                  shift=shift, **options)
                pipeline.TERRACED_PLANES = True
                metrics = evaluate(out.vertices, out.faces, vertices, faces,
                                   n_samples=args.samples)
                cds[name].append(1e5 * metrics["cd"])
        wins = int(np.sum(np.array(cds["agndc"]) < np.array(cds["undc"])))
        print(f"radius {radius} voxels, tilt {args.tilt}°: "
              + ", ".join(f"{name} {np.mean(v):.3f}" for name, v in cds.items())
              + f"; AGNDC better than UNDC on {wins} of {len(shifts)}", flush=True)


if __name__ == "__main__":
    main()
