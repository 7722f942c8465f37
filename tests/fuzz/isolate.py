"""Run one input through a reader in a forked child with a time and an address-space limit, and classify
what happened: refused cleanly, loaded a valid model, a traceback, garbage, a hang, a memory blow-up or a
native crash. Forking from a warm parent costs milliseconds, so thousands of inputs run in minutes."""
from __future__ import annotations

import faulthandler
import json
import os
import resource
import signal
import time
import traceback
from dataclasses import dataclass

OUTCOMES = ("refused", "loaded", "traceback", "garbage", "hang", "memory", "crash")
FAILURES = ("traceback", "garbage", "hang", "memory", "crash")


@dataclass
class Outcome:
    status: str
    detail: str = ""


def _vm_size() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def run_isolated(load, check, path, *, timeout: float = 10.0, memory: int = 2 << 30) -> Outcome:
    """``load(path)`` then ``check(result)`` (which raises AssertionError on garbage) in a child process.

    ``memory`` is what the child may allocate beyond what it inherits."""
    from model.errors import RigInputError
    limit = _vm_size() + memory
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child: never returns
        os.close(r)
        faulthandler.disable()   # a native crash is reported by the parent, not dumped on the terminal
        try:
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            try:
                result = load(path)
            except RigInputError as exc:
                msg = str(exc)
                one_sentence = msg.count("\n") == 0 and 0 < len(msg) < 600
                payload = ("refused", msg) if one_sentence else ("traceback", "not one sentence: " + msg[:300])
            else:
                try:
                    check(result)
                    payload = ("loaded", "")
                except AssertionError as exc:
                    payload = ("garbage", str(exc)[:500])
        except MemoryError:
            payload = ("memory", "MemoryError")
        except BaseException:
            payload = ("traceback", traceback.format_exc()[-1500:])
        try:
            os.write(w, json.dumps(payload).encode()[:60000])
        finally:
            os._exit(0)
    os.close(w)
    deadline = time.monotonic() + timeout
    status = None
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(r)
            return Outcome("hang", f"still running after {timeout:.0f} s")
        time.sleep(0.002)
    data = b""
    while True:
        chunk = os.read(r, 65536)
        if not chunk:
            break
        data += chunk
    os.close(r)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        return Outcome("memory" if sig == signal.SIGKILL else "crash", f"killed by signal {sig}")
    if not data:
        return Outcome("crash", f"exit status {status} with no report")
    kind, detail = json.loads(data)
    return Outcome(kind, detail)
