"""The runs whose compiled loops a fresh install carries (`qemjax._ahead`): what a new user meets first (the
README's commands and example) and each method, scheduler and mode on small meshes made in code."""
from __future__ import annotations

import contextlib
import io
import os
import tempfile
import warnings


def run_all(demo: bool = True) -> None:
    """Run every workload once, in a temporary folder (their warnings and output swallowed)."""
    import numpy as np

    import qemjax
    from qemjax import shapes
    from qemjax._sweep import config as sweep_config

    here = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings(), \
            contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        warnings.simplefilter("ignore")
        os.chdir(tmp)
        try:
            shapes.write_examples(tmp)
            # what the README's and docs/getting-started.md's commands run
            qemjax.simplify("bumpy.obj", target_faces=1000)
            qemjax.simplify("bumpy.obj", target_faces=1000, scheduler="greedy")
            qemjax.simplify("bumpy.obj", ratio=0.1, method="esqem", scheduler="greedy")
            qemjax.simplify("textured.obj", ratio=0.1)
            qemjax.simplify("textured.obj", ratio=0.1, scheduler="greedy")
            qemjax.simplify("bumpy.ply", ratio=0.2, feature_edges=np.loadtxt("creases.txt", dtype=np.int64))
            qemjax.lod_chain("bumpy.obj", ratios=[0.5, 0.1])
            qemjax.simplify("bumpy.obj", max_distance_rel=0.005)
            example = sweep_config.load("sweep_example.toml", out=os.path.join(tmp, "sweep.csv"))
            sweep_config.run(example, progress=False)
            if demo:
                qemjax.simplify(shapes.bumpy_sphere(7), ratio=0.02)
            m = qemjax.load("bumpy.ply")
            res = qemjax.simplify(m, ratio=0.1, method="esqem", scheduler="greedy", progress=False)
            qemjax.metrics.evaluate(m, res)
            qemjax.lod_chain(m, ratios=[0.5, 0.25, 0.1])
            qemjax.sweep(["bumpy.obj"], {"method": ["default", "classic", "line"]}, [0.1, 0.02],
                         metrics={"n_samples": 10_000}, progress=False)
            # a partitioned run (in this process: the workers compile in their own) and each format's reader
            part = qemjax.Partition(part_faces=1000, workers=1)
            qemjax.simplify("bumpy.ply", ratio=0.1, partition=part)
            qemjax.simplify("bumpy.obj", ratio=0.1, partition=part)
            tm = qemjax.load("bumpy.ply")
            import trimesh
            trimesh.Trimesh(tm.vertices, tm.faces, process=False).export("bumpy.stl")
            trimesh.Trimesh(tm.vertices, tm.faces, process=False).export("ascii.ply", encoding="ascii")
            qemjax.simplify("bumpy.stl", ratio=0.1, partition=part)
            qemjax.simplify("ascii.ply", ratio=0.1, partition=part)
            # vertices of high valence: the area method's rings wider than its kernels take (`area_host`)
            qemjax.simplify(shapes.double_cone(150), target_faces=200, method="area", progress=False)
            # each method and scheduler, open and closed meshes, locks, modes
            meshes = [shapes.bumpy_sphere(3), shapes.grid(24, hole=True), shapes.torus(n_major=24, n_minor=12)]
            for mesh in meshes:
                for method in qemjax.methods():
                    for scheduler in ("parallel", "greedy"):
                        with contextlib.suppress(ValueError, TypeError):
                            qemjax.simplify(mesh, ratio=0.3, method=method, scheduler=scheduler, progress=False)
                nv = len(mesh.vertices)
                locked = np.zeros(nv, bool)
                locked[:: 7] = True
                for scheduler in ("parallel", "greedy"):
                    qemjax.simplify(mesh, ratio=0.3, scheduler=scheduler, locked=locked, progress=False)
                    for topology in (qemjax.Topology(preserve_topology=False), qemjax.Topology(pair_threshold=0.05)):
                        qemjax.simplify(mesh, ratio=0.3, scheduler=scheduler, topology=topology, progress=False)
                qemjax.simplify_batch(mesh, [{"ratio": 0.3}, {"ratio": 0.2, "boundary_weight": 10.0}])
                # the shape term: the compiled glue, the late phase's loops and a batch's copies
                qemjax.simplify(mesh, ratio=0.3, quality_threshold=0.3, progress=False)
                qemjax.simplify_batch(mesh, [{"ratio": 0.3, "quality_threshold": 0.3},
                                             {"ratio": 0.2, "quality_threshold": 0.3}])
        finally:
            os.chdir(here)
