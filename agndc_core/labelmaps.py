"""Label maps (segmentations): one closed mesh per label, each where its label sits.

A label map is an (X, Y, Z) integer volume in a NIfTI, ``.npy`` or ``.npz`` file: 0 is the
background and every positive value one structure, as 3D Slicer, FreeSurfer or ITK-SNAP write
segmentations. Negative values are background too, as for ``gridio.load_grid``, which reads a
NIfTI label map as one mask (every positive label solid) and says so with a
``MergedLabelsWarning``. Here each label is its own grid and its own mesh::

    volume = load_label_map("seg.nii.gz")        # LabelMap: (X, Y, Z) values + (4, 4) affine
    volume.labels()                               # {label: voxel count}, ascending labels
    volume.grid(3)                                # VoxelGrid of label 3 alone, in world place
    for label, result in iter_remesh_labels(volume, labels=[1, 3], method="agndc"): ...

Cropping. ``LabelMap.grid`` crops a label to its bounding box plus ``CROP_MARGIN`` voxels and
moves the affine's origin to the crop's first voxel, so the mesh lands where the label is in the
volume. This gives the mesh of the uncropped label grid, vertex for vertex (to float rounding,
same order: ``tests/core/test_labelmaps.py``): ``remesh`` shows the network every grid framed the
same way around its occupied box, whatever empty margin surrounds it
(``inference.trained_window``); marching cubes, surface nets, the flat patches and the contouring
look only at the voxels near the surface; and the lattice cells keep their order under a shift.
Without the crop every label would pay for the whole volume in the stages that scan every lattice
point. ``remesh(reframe=False)`` shows the network the grid as given, so no crop is made then.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import AGNDCError, CancelledError, GridError
from .grid import MAX_VOXELS, VoxelGrid
from .gridio import (  # noqa: F401  (MergedLabelsWarning: part of this module's API)
    LABEL_EXTENSIONS,
    MergedLabelsWarning,
    shown_values,
)
from .methods import MESH_ONLY_METHODS

#: empty voxels kept around a label's bounding box when it is cropped (any margin gives the same
#: mesh, see the module docstring; two keep every surface cell's neighbours inside the crop)
CROP_MARGIN = 2
#: between a file's name and a label value in the names of per-label outputs: ``brain_label-3``
LABEL_TAG = "_label-"
#: labels above this have their bounding boxes found one label at a time, not in one pass
#: (``scipy.ndimage.find_objects`` lists a slot for every value up to the largest)
_ONE_PASS_MAX_LABEL = 1 << 20


@dataclass
class LabelMap:
    """An integer label volume placed in world space.

    Attributes:
        values: (X, Y, Z) integer labels (bool, whole-number floats are converted); 0 and
            negative values are background.
        affine: (4, 4) float64 index (voxel centres) -> world coordinates, as ``VoxelGrid``.
        source: the file name, for messages.
    """

    values: np.ndarray
    affine: np.ndarray = field(default_factory=lambda: np.eye(4))
    source: str = "array"

    def __post_init__(self) -> None:
        self.values = _as_label_values(self.values, self.source)
        # the affine checked as a grid's is (a one-voxel stand-in: the values are not binary)
        self.affine = VoxelGrid(np.zeros((1, 1, 1), dtype=bool), self.affine,
                                source=self.source).affine
        self._counts = None
        self._boxes = {}

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.values.shape)

    def labels(self) -> dict[int, int]:
        """{label: voxel count} of every positive label present, ascending labels."""
        if self._counts is None:
            labels, counts = np.unique(self.values[self.values > 0], return_counts=True)
            self._counts = dict(zip(labels.tolist(), counts.tolist()))
        return dict(self._counts)

    def select(self, wanted=None) -> list[int]:
        """The labels to mesh: every label present (``wanted`` None or empty), else ``wanted``
        (a list of ints or a ``parse_labels`` string) in its own order, duplicates dropped.

        Raises:
            GridError when the volume holds no label; AGNDCError naming the wanted labels that
            are not present, and the ones that are.
        """
        wanted = self.wanted(wanted)
        missing = [label for label in wanted if label not in self.labels()]
        if missing:
            raise AGNDCError(self.missing_message(missing))
        return wanted

    def wanted(self, wanted=None) -> list[int]:
        """``select``'s labels without the check that each is present: every label present
        (``wanted`` None or empty), else ``wanted`` in its own order, duplicates dropped. A batch
        meshes the present ones and reports each missing one (``missing_message``) on its own.

        Raises GridError when the volume holds no label.
        """
        present = self.labels()
        if not present:
            raise GridError(f"{self.source}: no label to mesh (every voxel is 0 or negative)")
        if isinstance(wanted, str):
            wanted = parse_labels(wanted)
        if not wanted:
            return list(present)
        return list(dict.fromkeys(int(label) for label in wanted))

    def missing_message(self, missing) -> str:
        """Why labels cannot be meshed: ``seg.nii.gz: no label 4; the labels present are 1, 3``."""
        return (f"{self.source}: no label {shown_values(list(missing))}; the labels present are "
                f"{shown_values(list(self.labels()))}")

    def grid(self, label: int, *, crop: bool = True, margin: int = CROP_MARGIN) -> VoxelGrid:
        """The grid of one label: (X', Y', Z') bool ``values == label`` and its affine.

        With ``crop`` the grid is the label's bounding box plus ``margin`` voxels (inside the
        volume), its affine moved to the box's first voxel, so its voxels keep their world
        positions; without, the whole volume. Raises GridError for a label not present.
        """
        lo, hi = self._box(int(label))
        if crop:
            lo = np.maximum(lo - margin, 0)
            hi = np.minimum(hi + margin, self.shape)
        else:
            lo, hi = np.zeros(3, dtype=np.int64), np.array(self.shape)
        box = tuple(slice(a, b) for a, b in zip(lo.tolist(), hi.tolist()))
        affine = self.affine.copy()
        affine[:3, 3] += affine[:3, :3] @ lo  # world position of the crop's voxel (0, 0, 0)
        return VoxelGrid(self.values[box] == label, affine,
                         source=f"{self.source} label {label}")

    def _box(self, label: int) -> tuple[np.ndarray, np.ndarray]:
        """(lo (3,), hi (3,)) int64 index bounds, ``hi`` exclusive, of one label's voxels."""
        if label not in self.labels():
            raise GridError(f"{self.source}: no label {label}")
        if label not in self._boxes:
            self._boxes.update(_bounding_boxes(self.values, list(self.labels())))
        return self._boxes[label]


def _as_label_values(values, source: str) -> np.ndarray:
    """(X, Y, Z) integer labels from an array; GridError naming what is wrong otherwise."""
    values = np.asarray(values)
    if values.ndim != 3 or min(values.shape) < 1:
        raise GridError(f"{source}: a label map must be a 3-D (X, Y, Z) array, got shape "
                        f"{values.shape}")
    if values.size > MAX_VOXELS:
        raise GridError(f"{source}: label map {values.shape} has {values.size:,} voxels, more "
                        f"than the {MAX_VOXELS:,} this remesher handles in memory")
    if values.dtype == bool:
        return values.astype(np.uint8)
    if values.dtype.kind in "iu":
        return values
    if values.dtype.kind == "f":
        whole = np.isfinite(values) & (values == np.round(values))
        if whole.all():
            return values.astype(np.int64)
        example = values[~whole].flat[0]
        raise GridError(f"{source}: not a label map: {example:g} is not a whole number "
                        "(labels are integers; threshold a probability map into a mask)")
    raise GridError(f"{source}: not a label map: values of type {values.dtype}")


def _bounding_boxes(values: np.ndarray, labels: list[int]) -> dict:
    """{label: (lo (3,), hi (3,))} int64 index bounds of each label (``hi`` exclusive)."""
    if max(labels) <= _ONE_PASS_MAX_LABEL:
        from scipy.ndimage import find_objects

        # one pass over the volume for every label; find_objects ignores 0, not negatives
        positive = values if values.min() >= 0 else np.where(values > 0, values, 0)
        objects = find_objects(positive, max_label=max(labels))
        slices = {label: objects[label - 1] for label in labels}
    else:  # a few huge label values: one pass per label
        slices = {label: _box_slices(values == label) for label in labels}
    return {label: (np.array([s.start for s in box], dtype=np.int64),
                    np.array([s.stop for s in box], dtype=np.int64))
            for label, box in slices.items()}


def _box_slices(mask: np.ndarray) -> tuple[slice, slice, slice]:
    """The bounding box of a non-empty (X, Y, Z) bool mask as three slices."""
    xy = mask.any(axis=2)
    axes = (xy.any(axis=1), xy.any(axis=0), mask.any(axis=(0, 1)))
    return tuple(slice(int(np.argmax(a)), len(a) - int(np.argmax(a[::-1]))) for a in axes)


def parse_labels(text: str | None) -> list[int] | None:
    """``"1,3,7"`` (commas and/or spaces) -> [1, 3, 7]; empty or None -> None (every label).

    Raises AGNDCError naming an entry that is not a whole number.
    """
    entries = (text or "").replace(",", " ").split()
    try:
        return [int(entry) for entry in entries] or None
    except ValueError:
        bad = next(entry for entry in entries if not entry.lstrip("+-").isdigit())
        raise AGNDCError(f"labels are whole numbers separated by commas, e.g. 1,3,7; got "
                         f"{bad!r}") from None


def load_label_map(path) -> LabelMap:
    """Read a label map from a NIfTI (.nii, .nii.gz), .npy or .npz file (``gridio``'s readers),
    keeping the file's affine. Raises GridFileError / GridError as ``gridio.load_grid``, and
    AGNDCError for a mesh file."""
    from .gridio import is_mesh_path, load_grid_values

    if is_mesh_path(path):  # said plainly: the readers would only call it an unknown grid
        raise AGNDCError(f"{Path(path).name}: --per-label reads a label map "
                         f"({' '.join(LABEL_EXTENSIONS)}), not a mesh")
    values, affine = load_grid_values(path)
    return LabelMap(values, affine, source=Path(path).name)


def as_label_map(source, affine=None) -> LabelMap:
    """A LabelMap from a LabelMap, a file path, or an (X, Y, Z) array (+ optional affine)."""
    if isinstance(source, LabelMap):
        return source
    if isinstance(source, (str, Path)):
        return load_label_map(source)
    return LabelMap(source, np.eye(4) if affine is None else affine)


def label_name(stem: str, label: int) -> str:
    """The name of one label's output: ``brain`` and 3 -> ``brain_label-3``."""
    return f"{stem}{LABEL_TAG}{int(label)}"


def label_output_path(path, label: int) -> Path:
    """Where one label's mesh is written: ``out/brain.obj`` and 3 -> ``out/brain_label-3.obj``."""
    path = Path(path)
    return path.with_name(label_name(path.stem, label) + path.suffix)


def label_estimate(grid: VoxelGrid, method: str, threads: int = 1) -> float:
    """Estimated seconds of remeshing one label's grid (``plan.estimate_seconds``; methods
    without a calibration row are timed as marching cubes)."""
    from .plan import CALIBRATION, estimate_seconds, grid_crossings

    key = method if method in CALIBRATION else "mc"
    return estimate_seconds(key, grid.shape, grid_crossings(grid.occupancy), threads=threads)


def iter_remesh_labels(source, options=None, *, labels=None, affine=None, progress=None,
                       cancel=None, crop: bool = True, reframe: bool = True,
                       **changes) -> Iterator[tuple[int, object]]:
    """Remesh every label of a label map on its own: yields (label, ``RemeshResult``) in turn.

    Args:
        source: a LabelMap, a label map file, or an (X, Y, Z) integer array (with ``affine``).
        options: the ``RemeshOptions`` of every label's remesh (grid methods only), with
            ``changes`` to its fields, as for ``pipeline.remesh``.
        labels: which labels (ints or a ``parse_labels`` string); None = every label present.
        progress: callable(fraction, message): each label gets a share of [0, 1] in proportion
            to its estimated time (``label_estimate``), its messages start with "label N: ".
        cancel: object with ``is_set()``, checked inside each remesh and between labels.
        crop: remesh each label cropped to its bounding box (the same mesh, faster: module
            docstring); False remeshes it in the whole volume.
        reframe: as for ``pipeline.remesh`` (False also turns ``crop`` off).

    Raises:
        AGNDCError for a mesh-only method or labels not present (before any remesh);
        CancelledError when cancelled.
    """
    from .options import RemeshOptions
    from .pipeline import subrange

    options = RemeshOptions.of(options, **changes)
    check_grid_method(options.method)
    volume = as_label_map(source, affine)
    chosen = volume.select(labels)
    weights = np.array([max(label_estimate(volume.grid(label), options.method), 1e-3)
                        for label in chosen])
    starts = np.concatenate([[0.0], np.cumsum(weights)]) / weights.sum()
    for label, lo, hi in zip(chosen, starts[:-1], starts[1:]):
        if cancel is not None and cancel.is_set():
            raise CancelledError("remesh cancelled")
        report = subrange(progress, lo, hi)
        if report is not None:
            report = _prefixed(report, f"label {label}: ")
        yield label, remesh_label(volume, label, options, progress=report, cancel=cancel,
                                  crop=crop, reframe=reframe)


def remesh_label(volume: LabelMap, label: int, options, *, progress=None, cancel=None,
                 crop: bool = True, reframe: bool = True):
    """The ``RemeshResult`` of one label of a label map (``iter_remesh_labels`` and the
    per-label batch job mesh each label through this): its grid, cropped unless ``crop`` or
    ``reframe`` is off (module docstring), remeshed with ``options`` (a ``RemeshOptions``)."""
    from .pipeline import remesh

    return remesh(volume.grid(label, crop=crop and reframe), options, progress=progress,
                  cancel=cancel, reframe=reframe)


def check_grid_method(method: str) -> None:
    """AGNDCError for a method that cannot mesh a label map (it needs a mesh's own surface)."""
    if method in MESH_ONLY_METHODS:
        raise AGNDCError(f"method {method!r} contours a mesh's own surface: a label map is a "
                         "voxel grid, choose a grid method")


def remesh_labels(source, options=None, **arguments) -> dict:
    """{label: ``RemeshResult``} of every chosen label (``iter_remesh_labels``, the same
    arguments), in its order."""
    return dict(iter_remesh_labels(source, options, **arguments))


def _prefixed(progress, prefix: str):
    return lambda fraction, message: progress(fraction, prefix + message)
