"""The single import seam between the add-on and ``agndc_core``.

In the built extension the core is vendored beside this file (``<extension>/agndc_core``) and
is imported relatively; in a development checkout it is the ``pip install -e .`` package. The
rest of the add-on does ``from ._core import pipeline, ...`` and never touches ``sys.path``.

Modules are imported on first use (PEP 562), so registering the add-on imports only what the
properties need (``plan``: numpy); scipy comes with ``gridio``/``metrics``/``pipeline``, and the
networks run in the core's numpy runtime (no torch).
"""

import importlib
from importlib.util import find_spec

#: the package the core is imported from: vendored in the built extension, else installed
BASE = (f"{__package__}.agndc_core" if find_spec(f"{__package__}.agndc_core") is not None
        else "agndc_core")
MODULES = ("checkpoint", "colors", "errors", "gridio", "labelmaps", "methods", "metrics",
           "options", "pipeline", "plan", "progress", "voxelize")
#: modules of the core's subpackages, by the name the add-on imports them as
SUBMODULES = {"parallel": "runtime.parallel"}

def __getattr__(name):
    if name == "core":
        return importlib.import_module(BASE)
    if name in MODULES:
        return importlib.import_module(f"{BASE}.{name}")
    if name in SUBMODULES:
        return importlib.import_module(f"{BASE}.{SUBMODULES[name]}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
