"""Which round implementation a parallel run takes: forced (the compiled loops or the numpy stages) and
recorded, for the scripts that compare the two paths on the same meshes."""
from __future__ import annotations

import contextlib


@contextlib.contextmanager
def recorded():
    """Yields a list that gets, for each run's round implementation, whether it is the compiled loops."""
    from qemjax._schedulers import parallel

    taken = []
    choose = parallel.driver.choose

    def recording(run, glue=True):
        rnd = choose(run, glue)
        taken.append(isinstance(rnd, parallel.LoopRound))
        return rnd
    parallel.driver.choose = recording
    try:
        yield taken
    finally:
        parallel.driver.choose = choose


@contextlib.contextmanager
def forced(path: str | None, faces: int = 0):
    """Runs take ``path``: "compiled" (the loops' face limit raised above ``faces``), "numpy" (the loops
    never fit), or None (the choice of their own)."""
    from qemjax._schedulers.parallel import selection

    fits, most = selection.fits, selection.MAX_FACES
    if path == "compiled":
        selection.MAX_FACES = max(most, faces)
    elif path == "numpy":
        selection.fits = lambda *a: False
    try:
        yield
    finally:
        selection.fits, selection.MAX_FACES = fits, most
