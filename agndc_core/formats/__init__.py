"""Byte-level readers and writers for the voxel file formats that need hand-written parsing
(``binvox``, MagicaVoxel ``vox``). They work on ``bytes`` and plain arrays only; file access,
format dispatch and the ``VoxelGrid`` wrapping live in ``agndc_core.gridio``."""
