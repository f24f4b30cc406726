"""qemjax: JAX-accelerated, batched triangle-mesh simplification.

The public API, by group (``qemjax.__all__`` lists it in this order):

- simplifying: `simplify` (per-vertex constraints: its ``locked`` and ``vertex_weights`` keywords), and
  `simplify_batch` / `simplify_cells` (many runs in shared rounds); `load`, `Mesh`;
- methods, the cost models as frozen settings objects: `QEM` (with its presets), `ESQEM`, `AreaDifference`,
  `LineQEM`, `ProbabilisticQEM`, their base `Method`, `register_method`, `methods` (also gathered in
  `qemjax.costs`);
- the run's other settings: `Topology`, `Attributes`, `Schedule`, `Partition`;
- results and records: `SimplifyResult`, `Contractions`, the multiresolution record (`Record`, `Level`,
  `load_record`), LOD chains (`lod_chain`, `LodChain`);
- parameter sweeps: `sweep`, `pareto_front`;
- the compilation cache: `cache` (JAX's persistent compilation cache, on by default);
- research tools, as modules: `metrics` (distances, triangle quality, topology, seams), `costs` (the cost
  models), `shapes` (meshes made in code, `shapes.write_examples`), `peers` (other simplifiers behind one
  call), `render` (quick pictures).
"""
# name -> (module, attribute): imported on first use (PEP 562), so that `import qemjax` and the command line's
# --version and --help stay light (no JAX, numba or trimesh until a name that needs them is used)
_PUBLIC = {
    # simplifying
    "simplify": ("._pipeline.api", "simplify"),
    "simplify_batch": ("._pipeline.api", "simplify_batch"),
    "simplify_cells": ("._pipeline.api", "simplify_cells"),
    "load": ("._io.mesh", "load"),
    "Mesh": ("._io.mesh", "Mesh"),
    # methods: the cost models
    "QEM": ("._costs.qem", "QEM"),
    "ESQEM": ("._costs.esqem", "ESQEM"),
    "AreaDifference": ("._costs.area", "AreaDifference"),
    "LineQEM": ("._costs.line", "LineQEM"),
    "ProbabilisticQEM": ("._costs.probabilistic", "ProbabilisticQEM"),
    "Method": ("._costs.base", "Method"),
    "register_method": ("._costs", "register"),
    "methods": ("._pipeline.api", "methods"),
    # the run's other settings
    "Topology": ("._options", "Topology"),
    "Attributes": ("._options", "Attributes"),
    "Schedule": ("._options", "Schedule"),
    "Partition": ("._options", "Partition"),
    # results and records
    "SimplifyResult": ("._record.result", "SimplifyResult"),
    "Contractions": ("._record.result", "Contractions"),
    "Record": ("._record.history", "Record"),
    "Level": ("._record.history", "Level"),
    "load_record": ("._record.history", "load_record"),
    "lod_chain": ("._pipeline.lod", "lod_chain"),
    "LodChain": ("._pipeline.lod", "LodChain"),
    # parameter sweeps
    "sweep": ("._sweep.run", "sweep"),
    "pareto_front": ("._sweep.pareto", "pareto_front"),
    # the compilation cache
    "cache": ("._kernels.cache", "cache"),
}
# research tools: public submodules, also imported on first use
_MODULES = ("metrics", "costs", "shapes", "peers", "render")
# ``from qemjax import *``: the names above, in their groups, then the research tools' modules
__all__ = [*_PUBLIC, *_MODULES]

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
