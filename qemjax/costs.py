"""The cost models (methods) in one namespace, for those who compare or write them: the built-in classes,
their base `Method`, and the registry (`register_method`, `methods`). The same objects as ``qemjax.QEM``
and the rest; docs/methods.md describes each, docs/design.md ("Adding a method") how to write one.

    >>> from qemjax import costs
    >>> costs.methods()
    >>> qemjax.simplify(mesh, ratio=0.1, method=costs.ESQEM(curvature_weight=0.1))
"""
from ._costs import register as register_method
from ._costs.area import AreaDifference
from ._costs.base import Method
from ._costs.esqem import ESQEM
from ._costs.line import LineQEM
from ._costs.probabilistic import ProbabilisticQEM
from ._costs.qem import QEM
from ._pipeline.api import methods

__all__ = ["QEM", "ESQEM", "AreaDifference", "LineQEM", "ProbabilisticQEM", "Method", "register_method", "methods"]
