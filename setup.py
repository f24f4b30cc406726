"""The package build compiles qemjax's host loops ahead (`qemjax._ahead`): their numba cache files go into the
wheel beside the modules, so a fresh install's first run loads them instead of compiling for half a minute.
Everything else is in pyproject.toml."""
import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithLoops(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False) or os.environ.get("QEMJAX_NO_AHEAD", "") not in ("", "0"):
            return  # an editable install compiles in its source tree on first use, or by `qemjax compile`
        lib = Path(self.build_lib)
        for old in list(lib.glob("qemjax/**/__pycache__/*.nb[ic]")):
            old.unlink()  # a former build's entries, for functions that may be gone
        env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
        env["PYTHONPATH"] = os.pathsep.join([str(lib.resolve())] + [p for p in [env.get("PYTHONPATH")] if p])
        print("qemjax: compiling the host loops ahead (QEMJAX_NO_AHEAD=1 skips this)", flush=True)
        done = subprocess.run([sys.executable, "-m", "qemjax._ahead", "--build"], env=env, cwd=str(lib))
        if done.returncode:  # the install still works: numba then compiles on first use
            print("qemjax: compiling ahead failed; the first run will compile instead", flush=True)
        for lock in list(lib.glob("qemjax/**/__pycache__/*.nbi.lock")):
            lock.unlink()  # the compiling processes' turns (`qemjax._mesh.compiled`): made again where needed


setup(cmdclass={"build_py": BuildWithLoops})
