"""What a fresh ``blendshape-studio`` process imports before it does any work (``model.scipy_import``): scipy's
array-API layer without the numpy submodules (f2py, testing, ...) its copy of numpy's namespace would load, and
numpy left exactly as it was: its ``__all__``, ``dir()`` and lazily loaded submodules unchanged."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_PROBE = """
import json, sys
{first}
import numpy
import scipy.sparse, scipy.ndimage, scipy.spatial, scipy.linalg
loaded = sorted(m for m in ("numpy.f2py", "numpy.testing", "numpy.polynomial", "charset_normalizer")
                if m in sys.modules)
state = {{"all": sorted(numpy.__all__),     # sorted: numpy builds it from a set (its order varies by process)
          "dir": sorted(dir(numpy)), "dir_in_dict": "__dir__" in vars(numpy)}}
# scipy works as before: array-API paths (ndimage, spatial, sparse, linalg) on numpy arrays
x = numpy.arange(12.0)
res = [scipy.ndimage.gaussian_filter1d(x, 1.5).round(9).tolist(),
       scipy.spatial.cKDTree(numpy.c_[x, x]).query([[2.2, 2.2]])[1].tolist(),
       (scipy.sparse.diags(x) @ x).tolist(), scipy.linalg.solve(numpy.eye(2) * 2, [2.0, 4.0]).tolist()]
import numpy.testing                                    # still importable on demand
numpy.testing.assert_allclose(numpy.random.default_rng(0).random(2).shape, (2,))
print(json.dumps({{"loaded": loaded, "state": state, "res": res}}))
"""


def _probe(first: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE.format(first=first)], capture_output=True, text=True,
                         cwd=ROOT, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return json.loads(out.stdout)


def test_scipy_loads_without_numpys_unused_submodules_and_numpy_is_left_as_it_was():
    lean, plain = _probe("import model.scipy_import"), _probe("")
    assert plain["loaded"] == ["charset_normalizer", "numpy.f2py", "numpy.polynomial", "numpy.testing"]  # scipy's
    assert lean["loaded"] == []
    assert lean["state"] == plain["state"]                # numpy's __all__ and dir() restored exactly
    assert lean["res"] == plain["res"]


def test_the_command_imports_it_before_its_own_imports_and_the_fork_server_too():
    from model.fork_server import WORKER_MODULES
    assert WORKER_MODULES[:2] == ("model.batch_env", "model.scipy_import")   # before anything loads scipy there
    code = ("import sys, app.launch\n"
            "try:\n    app.launch.main(['solve', '--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('numpy.f2py', 'numpy.testing') if m in sys.modules), "
            "'model.scipy_import' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.stdout.split("\n")[-2] == "[] True", out.stdout + out.stderr


_DOC_PROBE = """
import json, sys
{first}
import scipy._lib._docscrape as docscrape
parses = []
real_init = docscrape.NumpyDocString.__init__
def counting_init(self, *args, **kwargs):
    parses.append(1)
    real_init(self, *args, **kwargs)
docscrape.NumpyDocString.__init__ = counting_init
import scipy.ndimage, scipy.spatial.distance
from scipy._lib._array_api import xp_capabilities_table
f = scipy.ndimage.gaussian_filter
print(json.dumps({{"parses": len(parses), "registered": f in xp_capabilities_table,
                  "first_line": f.__doc__.strip().splitlines()[0]}}))
"""


def test_scipy_subpackages_load_without_parsing_every_docstring():
    """scipy's ``xp_capabilities`` decorator parses the docstring of every function it marks when its subpackage
    loads (~0.1 s of a fresh process); after ``model.scipy_import`` it does not (but for a few that rewrite a
    parameter's text), and the capabilities are still
    registered and the docstrings still the functions' own."""
    def probe(first: str) -> dict:
        out = subprocess.run([sys.executable, "-c", _DOC_PROBE.format(first=first)], capture_output=True, text=True,
                             cwd=ROOT, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        return json.loads(out.stdout)
    lean, plain = probe("import model.scipy_import"), probe("import scipy._lib._array_api")
    # left: the few decorators that rewrite a parameter's text (they need the parse)
    assert plain["parses"] > 50 and lean["parses"] < 0.05 * plain["parses"], (plain, lean)
    assert lean["registered"] and plain["registered"]
    assert lean["first_line"] == plain["first_line"] == "Multidimensional Gaussian filter."
    from model.scipy_import import _UnparsedDoc
    from scipy.ndimage import gaussian_filter
    assert "sigma" in [p.name for p in _UnparsedDoc(gaussian_filter)["Parameters"]]   # asked more: parsed then
