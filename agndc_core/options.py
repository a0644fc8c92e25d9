"""The options of a remesh, spelled once: what every front end fills and ``pipeline`` reads.

``agndc remesh`` and ``agndc batch`` (``cli.options_from_args``), the batch workers
(``batch_job.run_job``), the Blender add-on (``remesh.Settings.remesh_options``) and the Python
API describe a run with one ``RemeshOptions``. ``pipeline.remesh``, ``remesh_mesh`` and
``remesh_file`` take it as ``options`` and accept its fields as keyword overrides, so a script
can still write ``remesh(grid, method="mc")``. What belongs to one call only -- progress,
cancellation, ground-truth labels -- stays a separate argument.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .errors import AGNDCError


@dataclass(frozen=True)
class RemeshOptions:
    """How a grid or mesh is turned into a mesh (frozen and picklable: batch workers get it).

    Attributes:
        method: one of ``methods.METHODS`` (``MESH_ONLY_METHODS`` need a mesh).
        resolution: mesh input: voxels on the longest side of its bounding box.
        voxel_size: mesh input, instead of ``resolution``: voxels of at most this many world
            units (``pipeline.resolution_for_voxel_size``); None uses ``resolution``.
        model_index: .vox files: which model.
        checkpoint: learned methods: a .safetensors checkpoint; None = the shipped weights.
        device: "cpu" runs the networks in the numpy runtime (no torch); "cuda" (or any other
            torch device) in torch.
        threads: CPU threads of the network; None = every core this process may use.
        tile: lattice tile edge for large grids (learned methods); None = automatic.
        flat_patches: learned methods: each flat voxel-face patch that is not a terrace gets
            one depth, the terraces of a slightly tilted plane one plane, and a terrace that a
            step runs round (a recessed floor, a plateau) the middle of its layer where the
            network sees it flat but off that middle (``flatpatches.py``), so flat faces come
            out flat.
        normal_filter: learned methods: denoise the mesh keeping its creases
            (``normalfilter.py``).
        source_bounds: dual methods on a voxelised mesh: the faces that bound the shape lie on
            the mesh's bounding box.
        min_component_faces: drop connected components with fewer faces.
        decimate_error, target_faces: low poly (``decimate.py``): merge flat regions keeping
            creases, moving the surface by at most ``decimate_error`` voxels and/or down to
            about ``target_faces`` faces; None and None keep the full mesh.
    """

    method: str = "agndc"
    resolution: int = 64
    voxel_size: float | None = None
    model_index: int = 0
    checkpoint: str | None = None
    device: str = "cpu"
    threads: int | None = None
    tile: int | None = None
    flat_patches: bool = True
    normal_filter: bool = True
    source_bounds: bool = True
    min_component_faces: int = 0
    decimate_error: float | None = None
    target_faces: int | None = None

    @classmethod
    def of(cls, options: RemeshOptions | None = None, **changes) -> RemeshOptions:
        """``options`` (default: the defaults) with ``changes`` to its fields; an unknown name
        is an error that lists the known ones."""
        unknown = sorted(set(changes) - FIELD_NAMES)
        if unknown:
            raise AGNDCError(f"unknown remesh option(s) {', '.join(unknown)}; the options are "
                             f"{', '.join(sorted(FIELD_NAMES))}")
        return replace(options if options is not None else cls(), **changes)

    @property
    def low_poly(self) -> bool:
        return self.decimate_error is not None or self.target_faces is not None


FIELD_NAMES = frozenset(f.name for f in fields(RemeshOptions))
