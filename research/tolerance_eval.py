"""Score ``agndc eval`` with some of the package's tolerances set otherwise, to choose one.

    .venv/bin/python research/tolerance_eval.py DATA -o OUT --set terrace_round_share=0.85 \\
        [--set NAME=VALUE ...] [--res 64] [--shifts 3] [--methods agndc]

Each ``--set`` overrides one field of ``agndc_core.tolerances.tol`` (converted to the type of
its value) in this process before the evaluation; the rows are those ``agndc eval`` writes.
"""

from __future__ import annotations

from stage_eval import eval_parser, run_eval


def apply(settings: list[str]) -> None:
    """Set each NAME=VALUE on ``tol``, converting VALUE to the field's current type."""
    from agndc_core.tolerances import tol

    for setting in settings:
        name, _, value = setting.partition("=")
        if not hasattr(tol, name):
            raise SystemExit(f"no tolerance named {name!r}")
        setattr(tol, name, type(getattr(tol, name))(value))


def main() -> None:
    parser = eval_parser(__doc__, methods=True)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()
    apply(args.set)
    run_eval(args)


if __name__ == "__main__":
    main()
