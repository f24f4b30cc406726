"""The peer adapters, now `qemjax.peers` (kept importable here for the experiments that use them)."""
from qemjax.peers import *  # noqa: F401,F403
from qemjax.peers import MESHOPT_ERROR_LIMIT, PEER_PACKAGES, PEERS, _warmed, compact, run_peer  # noqa: F401
