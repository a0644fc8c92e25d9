"""The single import seam between the add-on and ``agndc_core``.

In the built extension the core is vendored beside this file (``<extension>/agndc_core``) and
is imported relatively; in a development checkout it is the ``pip install -e .`` package. The
rest of the add-on does ``from ._core import core, pipeline, ...`` and never touches ``sys.path``.
Importing this module imports numpy/scipy (not torch: the core loads torch on first use).
"""

from importlib.util import find_spec

if find_spec(f"{__package__}.agndc_core") is not None:  # built extension: vendored copy
    from . import agndc_core as core
    from .agndc_core import errors, gridio, metrics, pipeline
else:  # development checkout: the installed package
    import agndc_core as core
    from agndc_core import errors, gridio, metrics, pipeline

__all__ = ["core", "errors", "gridio", "metrics", "pipeline"]
