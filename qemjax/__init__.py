"""qemjax: JAX-accelerated, batched triangle-mesh simplification.

Public API: `simplify` (and `simplify_batch` / `simplify_cells`: many runs in shared rounds); the methods
as frozen settings objects (`QEM`, `ESQEM`, `AreaDifference`, `LineQEM`, `ProbabilisticQEM`, their base
`Method`,
`register_method`, `methods`), the run's other settings (`Topology`, `Attributes`, `Schedule`); `load`, `SimplifyResult`, `Contractions`, `Mesh`; the multiresolution record (`Record`, `Level`,
`load_record`, `lod_chain`, `LodChain`), parameter sweeps (`sweep`, `pareto_front`), and the `metrics` and
`shapes` (meshes made in code, `shapes.write_examples`) modules.
"""
from ._pipeline.api import methods as methods
from ._costs import register as register_method
from ._costs.area import AreaDifference as AreaDifference
from ._costs.base import Method as Method
from ._costs.esqem import ESQEM as ESQEM
from ._costs.line import LineQEM as LineQEM
from ._costs.probabilistic import ProbabilisticQEM as ProbabilisticQEM
from ._costs.qem import QEM as QEM
from ._pipeline.api import simplify as simplify
from ._pipeline.api import simplify_batch as simplify_batch
from ._pipeline.api import simplify_cells as simplify_cells
from ._io.mesh import Mesh as Mesh
from ._io.mesh import load as load
from ._pipeline.lod import LodChain as LodChain
from ._pipeline.lod import lod_chain as lod_chain
from ._options import Attributes as Attributes
from ._options import Schedule as Schedule
from ._options import Topology as Topology
from ._sweep.pareto import pareto_front as pareto_front
from ._record.history import Level as Level
from ._record.history import Record as Record
from ._record.history import load_record as load_record
from ._record.result import Contractions as Contractions
from ._record.result import SimplifyResult as SimplifyResult
from ._sweep.run import sweep as sweep

__version__ = "0.2.0"


def __getattr__(name):  # lazy submodules: importing qemjax stays light
    if name in ("metrics", "render", "shapes"):
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'qemjax' has no attribute {name!r}")
