"""Which method remeshes a grid whose AGNDC mesh comes out wrinkled all over.

``normalfilter.wrinkled_surface`` picks the meshes the normal filter leaves alone: few vertices
on planar patches and a middle share on detail, the scan-like organic shapes whose wrinkles are
finer than the voxels. On them the shipped AGNDC smooths away more of the wrinkles than UNDC,
which is closer to the surface on every such validation shape, so the pipeline remeshes such
a grid with the method ``methods.WRINKLED_METHODS`` names. This study scores ``agndc eval`` of
AGNDC with that choice replaced (``--instead none``: AGNDC's own mesh, as before the choice):

    .venv/bin/python research/wrinkled_routing.py DATA -o OUT --instead none --res 64
    .venv/bin/python research/wrinkled_routing.py DATA -o OUT --instead agndc_fast --shifts 3

``--methods agndc_fast`` scores the distilled network with the choice applied to it as well.
docs/experiments/wrinkled-surfaces.md has the numbers.
"""

from __future__ import annotations

from stage_eval import asked_method_everywhere, eval_parser, run_eval


def main() -> None:
    parser = eval_parser(__doc__)
    parser.add_argument("--instead", default="undc",
                        choices=("none", "undc", "agndc_fast", "surfacenets"),
                        help="the method that remeshes a wrinkled surface (none: the one asked)")
    args = parser.parse_args()

    from agndc_core import methods

    asked = args.methods.split(",")
    asked_method_everywhere()
    if args.instead != "none":
        methods.WRINKLED_METHODS.update({name: args.instead for name in asked
                                         if name != args.instead})
    print("wrinkled surfaces:", methods.WRINKLED_METHODS or "the method asked")
    run_eval(args)


if __name__ == "__main__":
    main()
