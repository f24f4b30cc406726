"""Output compaction, and the names the greedy scheduler, the locks and the pipeline still import from here
(defined in `device`, `runtime`, `qemjax._kernels.batching` and `qemjax._options`)."""
from __future__ import annotations

import numpy as np

from .._kernels.batching import DTYPE as DTYPE
from .._kernels.batching import bucket as bucket
from .._kernels.batching import set_rows as set_rows
from .._mesh.arrays import face_normals as face_normals
from .._options import Options as Options
from .device import start_merge as start_merge
from .device import start_price as start_price
from .runtime import gc_paused as gc_paused

