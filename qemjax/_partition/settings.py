"""`Partition`: how a partitioned run cuts, groups and runs its parts (frozen settings, as `Topology`)."""
from __future__ import annotations

import dataclasses
import os
from typing import Any


@dataclasses.dataclass(frozen=True)
class Partition:
    """Settings of a partitioned run (``simplify(path, ratio=..., partition=Partition(...))``, the command
    line's ``--partition``): the input is read in chunks and cut into parts of at most ``part_faces`` faces
    along the Morton order of the face centroids; each level simplifies groups of neighbouring parts in
    parallel with the vertices they share with other groups locked, then regroups so that those borders
    lie inside the next level's groups; the last level is one group, unlocked, run to the exact target.

    part_faces: the most faces one task reads (level 1: a part; later: a group of parts' outputs).
    budget: the faces kept before the last level, as a multiple of the target: a small budget leaves the
        locked borders most of the faces the interiors need, and the last level cannot win that back.
    reduction: each level but the last keeps about 1/reduction of its faces (at least ``budget`` × target).
    final_faces: the most faces the last level's single group may read; above it the run ends with its
        groups' borders still locked (``stats["partition"]["locked_share"]``, a warning).
    workers: local worker processes (None: every core; 1: in this process) when no ``client`` is given.
    client: a ``dask.distributed.Client``: the tasks run on its workers (a `LocalCluster`, dask-jobqueue,
        Kubernetes: any cluster whose workers see ``scratch``).
    scratch: the folder for the parts (a shared file system on a cluster). None: a temporary folder, removed
        when the run ends. A folder given is kept, and a run of the same input and settings resumes from
        the parts already in it.
    retries: how often a task whose worker died is run again.
    measure: measure the distance of the output from every input vertex and face centroid, part by part.
    """

    part_faces: int = 100_000
    budget: float = 4.0
    reduction: float = 4.0
    final_faces: int = 4_000_000
    workers: int | None = None
    client: Any = dataclasses.field(default=None, compare=False, repr=False)
    scratch: str | os.PathLike | None = None
    retries: int = 2
    measure: bool = True

    def __post_init__(self):
        def positive(name, value, kind=int, least=1):
            if not isinstance(value, (int, float)) or isinstance(value, bool) or value < least or \
                    (kind is int and value != int(value)):
                raise ValueError(f"Partition: {name} must be {'an integer' if kind is int else 'a number'} "
                                 f">= {least}, got {value!r}")
        positive("part_faces", self.part_faces, least=1000)
        positive("budget", self.budget, float, 1)
        positive("reduction", self.reduction, float, 1.5)
        positive("final_faces", self.final_faces)
        positive("retries", self.retries, least=0)
        if self.workers is not None:
            positive("workers", self.workers)

    @property
    def n_workers(self) -> int:
        """The local processes a run without a client uses."""
        if self.workers is not None:
            return int(self.workers)
        try:
            return len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            return os.cpu_count() or 1
