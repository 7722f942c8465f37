"""Fuzz the readers: ``python -m tests.fuzz.run [--per-reader N] [--seed S] [--readers a,b] [--out DIR]``.

Every input runs in a forked child with a 10 s and 2 GiB limit (tests/fuzz/isolate.py) and is classified
as refused, loaded (and valid), or a failure: traceback, garbage, hang, memory, crash. Failing inputs are
kept in --out (default: a temporary folder) with the reader's message, to reproduce them. Prints a JSON
summary on the last line; exit 1 if any input failed."""
from __future__ import annotations

import argparse
import json
import random
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from .isolate import FAILURES, run_isolated
from .targets import build_targets, mutate_input


def fuzz(per_reader: int, seed: int, readers: list[str] | None, out: Path, work: Path,
         timeout: float = 10.0) -> dict:
    from app.runtime import limit_blas_threads
    limit_blas_threads()
    targets = build_targets(work)
    names = readers or list(targets)
    summary = {"seed": seed, "per_reader": per_reader, "readers": {}}
    for name in names:
        t = targets[name]
        if "prepare" in t.extra:
            t.extra["prepare"]()
        rng = random.Random(f"{seed}:{name}")
        counts: Counter = Counter()
        failures = []
        start = time.perf_counter()
        for i in range(per_reader):
            seed_file = t.seeds[i % len(t.seeds)]
            data = mutate_input(t, seed_file, rng)
            folder = Path(tempfile.mkdtemp(dir=work, prefix=f"{name}-"))
            try:
                path = t.layout(seed_file, data, folder)
                outcome = run_isolated(t.load, t.check, path, timeout=timeout)
                counts[outcome.status] += 1
                if outcome.status in FAILURES:
                    keep = out / name / f"{i:05d}-{outcome.status}-{seed_file.name}"
                    keep.parent.mkdir(parents=True, exist_ok=True)
                    keep.write_bytes(data)
                    failures.append({"input": str(keep), "seed_file": seed_file.name, "status": outcome.status,
                                     "detail": outcome.detail[-600:]})
            finally:
                shutil.rmtree(folder, ignore_errors=True)
        summary["readers"][name] = {"counts": dict(counts), "seconds": round(time.perf_counter() - start, 1),
                                    "failures": failures}
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz.run")
    ap.add_argument("--per-reader", type=int, default=40)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--readers", help="comma-separated subset")
    ap.add_argument("--out", help="folder for failing inputs")
    ap.add_argument("--timeout", type=float, default=10.0)
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="bs-fuzz-"))
    out = Path(a.out) if a.out else tmp / "failures"
    try:
        s = fuzz(a.per_reader, a.seed, a.readers.split(",") if a.readers else None, out, tmp / "work", a.timeout)
    finally:
        shutil.rmtree(tmp / "work", ignore_errors=True)
        if not any(tmp.iterdir()):    # no failing input kept there
            tmp.rmdir()
    for name, r in s["readers"].items():
        print(f"{name:12s} {r['seconds']:7.1f} s  " + "  ".join(f"{k} {v}" for k, v in sorted(r["counts"].items())),
              file=sys.stderr)
    print(json.dumps(s))
    return 1 if any(f for r in s["readers"].values() for f in r["failures"]) else 0


if __name__ == "__main__":
    sys.exit(main())
