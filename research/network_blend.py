"""Two networks' vertices blended: ``agndc eval`` with AGNDC's prediction replaced by a weighted
mean of its vertices and another shipped network's on the same lattice.

The shipped networks err differently: on the validation family UNDC (surface nets plus a
learned correction) closes more of the organic shapes' headroom than AGNDC, AGNDC more of the
CAD and printed shapes'. Their cells are the same (the grid's surface cells), so their vertex
offsets can be averaged before the flat-patch stage, the contouring and the normal filter:

    .venv/bin/python research/network_blend.py DATA -o OUT --res 64 [--shifts 3] \
        --with undc --weight 0.5

``--weight`` is AGNDC's share (1 is AGNDC alone); the row is scored as ``agndc``.
"""

from __future__ import annotations

from stage_eval import eval_parser, run_eval_with_network


def main() -> None:
    parser = eval_parser(__doc__, methods=False)
    parser.add_argument("--with", dest="other", default="undc", choices=("undc", "agndc_fast"),
                        help="the network blended with AGNDC (its shipped weights)")
    parser.add_argument("--weight", type=float, default=0.5, help="AGNDC's share, 0..1")
    args = parser.parse_args()

    run_eval_with_network(args, args.other, lambda lattice, vertex, other: (
        args.weight * vertex + (1.0 - args.weight) * other()))


if __name__ == "__main__":
    main()
