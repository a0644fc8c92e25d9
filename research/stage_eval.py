"""The arguments and the run shared by the studies that score ``agndc eval`` with one stage of
the pipeline replaced (``flat_patch_depth.py``, ``mirror_border.py``, ``filter_passes.py``,
``filter_detail.py``): each replaces its stage, then calls ``run_eval``."""

from __future__ import annotations

import argparse


def eval_parser(doc: str, data_help: str = "folder of meshes (agndc val-data)",
                methods: bool = True) -> argparse.ArgumentParser:
    """A parser with the data folder, -o, --res, --samples, --shifts and (if ``methods``)
    --methods; a study adds its own options."""
    parser = argparse.ArgumentParser(description=doc.split("\n")[0])
    parser.add_argument("data", help=data_help)
    parser.add_argument("-o", "--out", required=True)
    if methods:
        parser.add_argument("--methods", default="agndc")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--samples", type=int, default=30_000)
    parser.add_argument("--shifts", type=int, default=0)
    return parser


def run_eval(args: argparse.Namespace) -> None:
    """``agndc eval`` of the parsed arguments (AGNDC unless the study takes --methods)."""
    from agndc_core.cli import main as agndc

    agndc(["eval", args.data, "--methods", getattr(args, "methods", "agndc"), "--res",
           str(args.res), "--samples", str(args.samples), "--shifts", str(args.shifts),
           "-o", args.out])
