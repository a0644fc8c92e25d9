"""The core's own error types: every user-facing failure is one of these, with a message that names
the file or object and the problem. Front ends (CLI, Blender operator, batch script) catch
``AGNDCError`` and show its message; anything else is a bug."""


class AGNDCError(RuntimeError):
    """Base class of every error the remesher reports to users."""


class GridError(AGNDCError, ValueError):
    """A voxel grid is unusable: wrong shape or dtype, non-binary values, empty, too large."""


class GridFileError(AGNDCError):
    """A grid or mesh file is missing, corrupt, truncated or in an unsupported format."""


class MeshError(AGNDCError, ValueError):
    """An input mesh is unusable (no faces, non-finite coordinates, zero extent)."""


class ModelError(AGNDCError):
    """A checkpoint is missing, malformed, or does not match its config."""


class CancelledError(AGNDCError):
    """The user cancelled a long operation (Esc in Blender, Ctrl-C in the CLI)."""
