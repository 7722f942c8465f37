"""Peak memory of loading a studio-scale rig (issue 20: "the 422k-vertex × 228-shape rig loads with peak memory
under 2x its delta array"). The rig is ICT subdivided (``studio_rig``) with 228 local shapes (``split_shapes``),
saved once as a project (the format a rig of this size lives in; its OBJ folder would be about 8 GB of text) and
cached in the temporary folder. A fresh process imports the readers, resets its peak resident memory (Linux: /proc/self/clear_refs) and
notes its resident size, loads the project with ``model.readers.load_rig`` and reads its peak (VmHWM): the growth
over the delta array's size is the ratio asserted. (ru_maxrss would not do: a child process starts with its
parent's peak.)

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_studio_memory.py --benchmark-only -s

levels=1 (106k vertices, 0.58 GB of deltas) runs in about a minute; levels=2 (422k, 2.3 GB) needs about 4 GB while
the project is first written and several minutes of CPU on a shared machine.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.benchmarks.studio_rig import CACHE, MEMORY_PROBE, studio_rig
from tests.benchmarks.studio_shapes import split_shapes

SHAPES = 228

_PROBE = MEMORY_PROBE + """
from model.readers import load_rig
import numpy as np
before = reset_peak()
rig = load_rig(sys.argv[1])
print(json.dumps({"before": before, "after": status("VmHWM"), "deltas": rig.deltas.nbytes,
                  "shape": list(rig.deltas.shape), "finite": bool(np.isfinite(rig.deltas[-1]).all())}))
"""


def studio_project(levels: int, n_shapes: int = SHAPES):
    """The project file of the ``levels`` studio rig with ``n_shapes`` shapes (built once, then cached)."""
    path = CACHE / f"ict_subdivided_{levels}_{n_shapes}shapes.bsproj"
    if path.exists():
        return path
    from model.project import Project, save_project
    from model.rig import Rig
    neutral, counts, idx, deltas = studio_rig(levels)
    shapes = split_shapes(neutral, deltas, n_shapes)
    del deltas
    rig = Rig(neutral=neutral, face_counts=counts, face_indices=idx, shape_names=[f"s{k:03d}" for k in range(n_shapes)],
              deltas=shapes.astype(np.float64), name=f"studio{levels}")
    del shapes
    save_project(Project(rig=rig), path)
    return path


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_rig_load_peak_memory(benchmark, ict_dir, levels):
    path = studio_project(levels)
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))

    def load():
        out = subprocess.run([sys.executable, "-c", _PROBE, str(path)], capture_output=True, text=True, env=env,
                             cwd=root, check=True)
        return json.loads(out.stdout)

    r = benchmark.pedantic(load, rounds=1, iterations=1)
    ratio = (r["after"] - r["before"]) / r["deltas"]
    benchmark.extra_info.update(vertices=r["shape"][1], shapes=r["shape"][0], delta_bytes=r["deltas"],
                                peak_growth_bytes=r["after"] - r["before"], ratio=ratio)
    print(f"\n{r['shape'][0]} shapes x {r['shape'][1]} vertices: deltas {r['deltas'] / 2**30:.2f} GiB, "
          f"peak grew {(r['after'] - r['before']) / 2**30:.2f} GiB while loading ({ratio:.2f}x the deltas)")
    assert r["shape"][0] == SHAPES and r["finite"]
    assert ratio < 2.0
