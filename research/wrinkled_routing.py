"""A grid whose AGNDC mesh comes out wrinkled all over, remeshed by another method instead.

``normalfilter.wrinkled_surface`` picks the meshes the normal filter leaves alone: few vertices
on planar patches and a middle share on detail (the scan-like organic shapes whose wrinkles are
finer than the voxels). On the validation family's wrinkled figurines UNDC is closer than
AGNDC. This study scores ``agndc eval`` of AGNDC with every grid the rule picks remeshed by
``--instead`` (the whole pipeline of that method, its shipped weights), the other grids left to
AGNDC:

    .venv/bin/python research/wrinkled_routing.py DATA -o OUT --instead undc --res 64
    .venv/bin/python research/wrinkled_routing.py DATA -o OUT --instead undc --shifts 3 \\
        --checkpoint runs/undc_wrinkled16/final.safetensors

The rows are AGNDC's (``agndc``); docs/experiments/wrinkled-surfaces.md has the numbers.
"""

from __future__ import annotations

from stage_eval import eval_parser, run_eval


def main() -> None:
    parser = eval_parser(__doc__, methods=False)
    parser.add_argument("--instead", default="undc", choices=("undc", "agndc_fast"),
                        help="the method that remeshes a grid whose AGNDC mesh is wrinkled")
    parser.add_argument("--checkpoint", default=None, help="its weights (default: shipped)")
    args = parser.parse_args()

    from agndc_core import normalfilter, pipeline

    plain_remesh, plain_rule = pipeline.remesh, normalfilter.wrinkled_surface
    picked = []

    def rule(*rule_args, **rule_options):  # the filter's reading, remembered
        wrinkled = plain_rule(*rule_args, **rule_options)
        picked.append(wrinkled)
        return wrinkled

    def remesh(grid, options=None, **changes):
        picked.clear()
        result = plain_remesh(grid, options, **changes)
        if result.method != "agndc" or not any(picked):
            return result
        changes.update(method=args.instead, checkpoint=args.checkpoint, progress=None)
        instead = plain_remesh(grid, options, **changes)
        instead.method, instead.seconds = "agndc", result.seconds + instead.seconds
        return instead

    normalfilter.wrinkled_surface = rule
    pipeline.remesh = remesh  # remesh_mesh looks it up on every call
    run_eval(args)


if __name__ == "__main__":
    main()
