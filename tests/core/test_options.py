"""RemeshOptions: the one spelling of a run's options (options.py)."""

import dataclasses

import numpy as np
import pytest

from agndc_core import AGNDCError, RemeshOptions, remesh
from agndc_core.cli import _parser, options_from_args


def test_options_and_keyword_overrides_give_the_same_run():
    occupancy = np.zeros((12, 12, 12), dtype=bool)
    occupancy[3:9, 3:8, 2:10] = True
    by_options = remesh(occupancy, RemeshOptions(method="surfacenets", min_component_faces=3))
    by_keywords = remesh(occupancy, method="surfacenets", min_component_faces=3)
    overridden = remesh(occupancy, RemeshOptions(method="agndc"), method="surfacenets",
                        min_component_faces=3)
    for other in (by_keywords, overridden):
        np.testing.assert_array_equal(other.vertices, by_options.vertices)
        np.testing.assert_array_equal(other.faces, by_options.faces)
    assert by_options.method == "surfacenets"


def test_an_unknown_option_names_the_known_ones():
    with pytest.raises(AGNDCError, match="unknown remesh option.*metod.*the options are.*method"):
        RemeshOptions.of(metod="mc")
    with pytest.raises(AGNDCError, match="metod"):
        remesh(np.ones((3, 3, 3), dtype=bool), metod="mc")


def test_the_cli_fills_every_field_from_its_flags():
    """agndc remesh and agndc batch share _add_remesh_options: every option has its flag."""
    args = _parser().parse_args(["remesh", "in.stl", "-o", "out.obj", "--method", "sharp",
                                 "--res", "96", "--model-index", "2", "--checkpoint", "w.st",
                                 "--device", "cuda", "--threads", "3", "--no-flat-patches",
                                 "--no-normal-filter", "--no-source-bounds",
                                 "--min-component-faces", "7", "--target-faces", "900"])
    options = options_from_args(args)
    assert options == RemeshOptions(method="sharp", resolution=96, model_index=2,
                                    checkpoint="w.st", device="cuda", threads=3,
                                    flat_patches=False, normal_filter=False,
                                    source_bounds=False, min_component_faces=7,
                                    target_faces=900)
    batch = _parser().parse_args(["batch", "d", "-o", "out", "--voxel-size", "0.5",
                                  "--decimate-error", "0.25"])
    assert options_from_args(batch) == RemeshOptions(voxel_size=0.5, decimate_error=0.25)
    # every field but the tile (set by the pipeline) comes from a flag
    assert {f.name for f in dataclasses.fields(RemeshOptions)} - {"tile"} <= {
        "method", "resolution", "voxel_size", "model_index", "checkpoint", "device", "threads",
        "flat_patches", "normal_filter", "source_bounds", "min_component_faces",
        "decimate_error", "target_faces"}
