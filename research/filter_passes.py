"""``agndc eval`` with fields of the normal filter's parameters replaced.

The pipeline filters every learned method's mesh with ``normalfilter.DEFAULT``; this study
replaces fields of it (``NormalFilter``) and scores AGNDC, e.g. the detail rule's thresholds
and pass counts:

    .venv/bin/python research/filter_passes.py DATA detail_degrees=8 -o OUT --res 64
    .venv/bin/python research/filter_passes.py DATA detail_vertex_iterations=10 -o OUT --shifts 3

(the fields right after DATA: argparse takes no positional after an option.)

(``detail_vertex_iterations=10`` is the full update everywhere.) docs/experiments/normal-filter.md
("Lighter on detail") has the measurements.
"""

from __future__ import annotations

import argparse
import dataclasses

from stage_eval import eval_parser, run_eval


def parse_field(text: str) -> tuple[str, object]:
    """"name=value" -> (name, value), the value typed as the ``NormalFilter`` field is."""
    from agndc_core.normalfilter import NormalFilter

    name, _, value = text.partition("=")
    fields = {field.name: field.type for field in dataclasses.fields(NormalFilter)}
    if name not in fields or not value:
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE with FIELD one of {list(fields)}")
    return name, (float(value) if fields[name] in (float, "float") else int(value))


def main() -> None:
    parser = eval_parser(__doc__, "folder of meshes (agndc val-data, or the dev meshes)",
                         methods=False)
    parser.add_argument("fields", nargs="*", type=parse_field, help="NormalFilter FIELD=VALUE")
    args = parser.parse_args()

    from agndc_core import normalfilter

    # filter_mesh's default argument was bound at import: pass the replaced parameters instead
    params = dataclasses.replace(normalfilter.DEFAULT, **dict(args.fields))
    plain = normalfilter.filter_mesh

    def filter_with_params(vertices, faces, _params=None, fixed_vx3=None, check=None,
                           planar_v=None):
        return plain(vertices, faces, params, fixed_vx3, check, planar_v)

    # the pipeline imports filter_mesh when it runs the stage, so it finds this one
    normalfilter.filter_mesh = filter_with_params
    print(params)
    run_eval(args)


if __name__ == "__main__":
    main()
