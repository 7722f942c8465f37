"""Exporting a studio-scale rig for an engine (File ▸ Export Rig, ``blendshape-studio export``): the 228-shape
projects of ``test_bench_studio_memory`` (ICT subdivided to 106k and 422k vertices) written as a binary glTF and a
USD crate, each in a fresh process, as the command runs. Measured: the export's time and its peak memory over what
the loaded rig holds (Linux: /proc/self/clear_refs resets the peak after the load; VmHWM is read after the write),
against the rig's delta array. Before (the code of 2026-12-06 morning, this benchmark, a busy machine): at 422k
vertices a .glb took 29.1 s and its peak grew 4.51 GiB, 2.10x the deltas (the deltas concatenated, then turned into
the export's units: two copies; the file joined in memory three times); a .usdc 23.7 s, 4.43 GiB (two more
(K, V, 3) temporaries for its extent). After, in the same minutes: 10.4 s, 0.70 GiB (0.32x) and 8.6 s, 0.68 GiB
(0.31x): a shape's offsets made as the writer takes it (``model.export.ShapeDeltas``), the .glb written a buffer
view at a time.

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_studio_export.py --benchmark-only -s
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.benchmarks.studio_rig import MEMORY_PROBE
from tests.benchmarks.test_bench_studio_memory import studio_project

_PROBE = MEMORY_PROBE + """
from model.readers import load_rig
from model.export import export_rig
rig = load_rig(sys.argv[1])
before = reset_peak()
t0 = time.perf_counter()
export_rig(rig, sys.argv[2])
seconds = time.perf_counter() - t0
print(json.dumps({"before": before, "after": status("VmHWM"), "deltas": rig.deltas.nbytes, "seconds": seconds,
                  "shape": list(rig.deltas.shape)}))
"""


@pytest.mark.parametrize("suffix", [".glb", ".usdc"])
@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_export_peak_memory(benchmark, tmp_path, levels, suffix):
    path = studio_project(levels)
    out = tmp_path / f"studio{levels}{suffix}"
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))

    def export():
        done = subprocess.run([sys.executable, "-c", _PROBE, str(path), str(out)], capture_output=True, text=True,
                              env=env, cwd=root, check=True)
        return json.loads(done.stdout)

    r = benchmark.pedantic(export, rounds=1, iterations=1)
    grew = r["after"] - r["before"]
    benchmark.extra_info.update(vertices=r["shape"][1], seconds=round(r["seconds"], 2), peak_growth_bytes=grew,
                                ratio=round(grew / r["deltas"], 2), file_bytes=out.stat().st_size)
    print(f"\n{suffix} of {r['shape'][0]} shapes x {r['shape'][1]:,} vertices: {r['seconds']:.1f} s, "
          f"{out.stat().st_size / 2**20:.0f} MiB written, peak grew {grew / 2**30:.2f} GiB over the loaded rig "
          f"({grew / r['deltas']:.2f}x its deltas, {r['deltas'] / 2**30:.2f} GiB)")
    assert out.stat().st_size > 0
