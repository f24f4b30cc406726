"""Host-side schedulers that decide which pairs to contract, in which order.

``greedy``: Garland & Heckbert's priority queue, one contraction at a time (the quality reference).
"""
