"""``agndc eval`` with the normal filter chosen per mesh: as shipped (no vertex update on a mesh
that ``normalfilter.wrinkled_surface`` calls wrinkled all over, a scan-like organic shape), on
every mesh, or on none.

The bilateral filter removes the network's cell-to-cell noise and flattens whatever bends as
little over a few cells: on wrinkled figurines that is the surface itself, and the filter costs
them 1-11 % of their CD while every other kind of shape gains from it
(docs/experiments/normal-filter.md, "No filter on wrinkled surfaces").

    .venv/bin/python research/filter_per_shape.py DATA -o OUT --where always --res 128
    .venv/bin/python research/filter_per_shape.py DATA -o OUT --where none --log OUT.txt \\
        --cache runs/pred_cache

``--log`` appends, per remeshed grid, its vertex count and the shares of its vertices on planar
patches, at creases and on detail (what the rule reads). ``--cache`` keeps each grid's network
prediction on disk, so that the variants rerun only contouring, filter and metrics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from stage_eval import eval_parser, run_eval_cached


def logged(filter_mesh, log: Path, params):
    """``filter_mesh`` that first appends "vertices planar_share crease_share detail_share"
    to ``log``."""
    from agndc_core import normalfilter as nf

    def run(vertices, faces, _params=None, fixed_vx3=None, check=None, planar_v=None):
        faces_ = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        vertices_ = np.asarray(vertices, dtype=np.float64)
        _, incidence, normals = nf.filtered_normals(vertices_, faces_, params, check)
        spread = nf.normal_spread(faces_, incidence, normals)
        planar = 0.0 if planar_v is None else float(np.mean(planar_v))
        with open(log, "a") as handle:
            handle.write(f"{len(vertices_)} {planar:.5f} "
                         f"{np.mean(spread > params.crease_degrees):.5f} "
                         f"{np.mean(spread > params.detail_degrees):.5f}\n")
        return filter_mesh(vertices, faces, _params, fixed_vx3, check, planar_v)

    return run


def main() -> None:
    parser = eval_parser(__doc__, methods=False, cache=True)
    parser.add_argument("--where", choices=("shipped", "always", "none"), default="shipped",
                        help="shipped: the pipeline's filter (wrinkled surfaces left alone); "
                        "always: the filter on every mesh; none: no filter")
    parser.add_argument("--log", type=Path, default=None, help="append, per filtered mesh: "
                        "vertices, and the shares on planar patches, at creases and on detail")
    args = parser.parse_args()

    import dataclasses

    from agndc_core import normalfilter

    params = normalfilter.DEFAULT
    if args.where == "always":  # no mesh has under 0 % of its vertices on planar patches
        params = dataclasses.replace(params, wrinkled_planar_share=0.0)
    plain = normalfilter.filter_mesh
    if args.where == "none":
        def replacement(vertices, faces, _params=None, fixed_vx3=None, check=None,
                        planar_v=None):
            return np.asarray(vertices, dtype=np.float64).copy()
    else:
        def replacement(vertices, faces, _params=None, fixed_vx3=None, check=None,
                        planar_v=None):
            return plain(vertices, faces, params, fixed_vx3, check, planar_v)
    if args.log is not None:
        normalfilter.filter_mesh = logged(replacement, args.log, params)
    else:
        normalfilter.filter_mesh = replacement
    print(params, args.where)
    run_eval_cached(args)


if __name__ == "__main__":
    main()
