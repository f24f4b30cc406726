"""qemjax: JAX-accelerated, batched triangle-mesh simplification.

Public API: `simplify` (and `simplify_batch` / `simplify_cells`: many runs in shared rounds); the methods
as frozen settings objects (`QEM`, `ESQEM`, `AreaDifference`, `LineQEM`, `ProbabilisticQEM`, their base
`Method`,
`register_method`, `methods`), the run's other settings (`Topology`, `Attributes`, `Schedule`); `load`, `SimplifyResult`, `Contractions`, `Mesh`; the multiresolution record (`Record`, `Level`,
`load_record`, `lod_chain`, `LodChain`), parameter sweeps (`sweep`, `pareto_front`), and the `metrics` and
`shapes` (meshes made in code, `shapes.write_examples`) modules; `cache` (JAX's persistent compilation
cache, on by default).
"""
# name -> (module, attribute): imported on first use (PEP 562), so that `import qemjax` and the command line's
# --version and --help stay light (no JAX, numba or trimesh until a name that needs them is used)
_PUBLIC = {
    "methods": ("._pipeline.api", "methods"),
    "register_method": ("._costs", "register"),
    "AreaDifference": ("._costs.area", "AreaDifference"),
    "Method": ("._costs.base", "Method"),
    "ESQEM": ("._costs.esqem", "ESQEM"),
    "LineQEM": ("._costs.line", "LineQEM"),
    "ProbabilisticQEM": ("._costs.probabilistic", "ProbabilisticQEM"),
    "QEM": ("._costs.qem", "QEM"),
    "simplify": ("._pipeline.api", "simplify"),
    "simplify_batch": ("._pipeline.api", "simplify_batch"),
    "simplify_cells": ("._pipeline.api", "simplify_cells"),
    "Mesh": ("._io.mesh", "Mesh"),
    "load": ("._io.mesh", "load"),
    "LodChain": ("._pipeline.lod", "LodChain"),
    "lod_chain": ("._pipeline.lod", "lod_chain"),
    "Attributes": ("._options", "Attributes"),
    "Schedule": ("._options", "Schedule"),
    "Topology": ("._options", "Topology"),
    "Partition": ("._options", "Partition"),
    "pareto_front": ("._sweep.pareto", "pareto_front"),
    "Level": ("._record.history", "Level"),
    "Record": ("._record.history", "Record"),
    "load_record": ("._record.history", "load_record"),
    "Contractions": ("._record.result", "Contractions"),
    "SimplifyResult": ("._record.result", "SimplifyResult"),
    "sweep": ("._sweep.run", "sweep"),
    "cache": ("._kernels.cache", "cache"),
}
_MODULES = ("metrics", "render", "shapes")  # public submodules, also imported on first use
__all__ = list(_PUBLIC)  # ``from qemjax import *``: the same names as when they were imported eagerly

__version__ = "0.2.0"


def _version_line() -> str:
    """What ``qemjax --version`` prints: this version and the installed JAX's (read from its package metadata,
    without importing JAX)."""
    from importlib.metadata import version

    return f"qemjax {__version__} (jax {version('jax')})"


def __getattr__(name):
    import importlib.util

    if name in _PUBLIC:
        module, attr = _PUBLIC[name]
        value = getattr(importlib.import_module(module, __name__), attr)
        globals()[name] = value  # once: later lookups are plain attribute reads
        return value
    if name in _MODULES or (name.startswith("_") and not name.startswith("__")
                            and importlib.util.find_spec(f"{__name__}.{name}") is not None):
        return importlib.import_module(f"{__name__}.{name}")  # a submodule not imported yet
    raise AttributeError(f"module 'qemjax' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC) | set(_MODULES))
