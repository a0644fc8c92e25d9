"""The arguments and the run shared by the studies that score ``agndc eval`` with one stage of
the pipeline replaced (``flat_patch_depth.py``, ``mirror_border.py``, ``filter_passes.py``,
``filter_detail.py``, ``filter_per_shape.py``, ``flat_terraces.py``, ``crease_cells.py``,
``network_blend.py``, ``thin_routing.py``): each replaces its stage, then calls ``run_eval``
(``run_eval_cached`` when the stage comes after the network and its predictions may be kept on
disk, ``run_eval_with_prediction`` when the stage is the network's prediction,
``run_eval_with_network`` for a second network beside AGNDC). ``high_margin.py`` replaces no
stage: it sets the learned methods' ``high_margin`` in the registry, then calls ``run_eval``."""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path


def eval_parser(doc: str, data_help: str = "folder of meshes (agndc val-data)",
                methods: bool = True, cache: bool = False) -> argparse.ArgumentParser:
    """A parser with the data folder, -o, --res, --samples, --shifts, (if ``methods``)
    --methods and (if ``cache``) --cache for ``run_eval_cached``; a study adds its own
    options."""
    parser = argparse.ArgumentParser(description=doc.split("\n")[0])
    parser.add_argument("data", help=data_help)
    parser.add_argument("-o", "--out", required=True)
    if methods:
        parser.add_argument("--methods", default="agndc")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--samples", type=int, default=30_000)
    parser.add_argument("--shifts", type=int, default=0)
    if cache:
        parser.add_argument("--cache", type=Path, default=None,
                            help="keep the network's predictions in this folder")
    return parser


def run_eval(args: argparse.Namespace) -> None:
    """``agndc eval`` of the parsed arguments (AGNDC unless the study takes --methods)."""
    from agndc_core.cli import main as agndc

    agndc(["eval", args.data, "--methods", getattr(args, "methods", "agndc"), "--res",
           str(args.res), "--samples", str(args.samples), "--shifts", str(args.shifts),
           "-o", args.out])


def run_eval_with_prediction(args: argparse.Namespace, replace) -> None:
    """``run_eval`` with the pipeline's vertex prediction replaced: ``replace(method, lattice,
    predict)`` returns the (X, Y, Z, 3) cell offsets of ``method`` on ``lattice``, and
    ``predict(method, lattice)`` is the pipeline's own prediction, with the call's other
    arguments (checkpoint, threads, framing)."""
    from agndc_core import pipeline

    original = pipeline._predict

    def replaced(method, lattice, *rest, **options):
        return replace(method, lattice,
                       lambda which, points: original(which, points, *rest, **options))

    pipeline._predict = replaced
    run_eval(args)


def run_eval_with_network(args: argparse.Namespace, other: str, combine) -> None:
    """``run_eval`` with AGNDC's vertices replaced by ``combine(lattice, vertex, other_vertex)``:
    ``vertex`` AGNDC's (X, Y, Z, 3) cell offsets, ``other_vertex()`` those of the shipped network
    ``other`` on the same lattice (predicted only when called)."""

    def replace(method, lattice, predict):
        vertex = predict(method, lattice)
        if method != "agndc":
            return vertex
        return combine(lattice, vertex, lambda: predict(other, lattice))

    run_eval_with_prediction(args, replace)


def cached(cache: Path):
    """A ``run_eval_with_prediction`` replacement that keeps each prediction on disk (keyed by
    the lattice and the method: clear the folder when the weights change)."""
    import numpy as np

    cache.mkdir(parents=True, exist_ok=True)

    def replace(method, lattice, predict):
        key = hashlib.sha1(np.ascontiguousarray(lattice).tobytes()
                           + str((method, lattice.shape)).encode()).hexdigest()
        path = cache / f"{key}.npy"
        if path.exists():
            return np.load(path)
        vertex = predict(method, lattice)
        np.save(path, vertex)
        return vertex

    return replace


def run_eval_cached(args: argparse.Namespace) -> None:
    """``run_eval``, with the network's predictions kept in ``args.cache`` when it is set, so
    that a study's variants rerun only the stages after the network."""
    if args.cache is None:
        run_eval(args)
    else:
        run_eval_with_prediction(args, cached(args.cache))


def flatten_writing(flatten, lattice, vertex, in_place: bool, pinned):
    """``flatten(lattice, vertex, in_place=..., pinned=...)`` (``flatten_patches`` or a study's
    replacement of it) -> (its output, the (X, Y, Z, 3) bool coordinates this call wrote): the
    studies that act on the patches a call placed, and not on coordinates pinned before."""
    import numpy as np

    mine = np.zeros(np.shape(vertex), dtype=bool) if pinned is None else pinned
    before = mine.copy()
    out = flatten(lattice, vertex, in_place=in_place, pinned=mine)
    return out, mine & ~before
