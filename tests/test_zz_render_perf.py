import time, os, numpy as np
from tests.gui_helpers import make_window, open_and_wait

def test_render(qtbot, tmp_path, ict_dir):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=120000)
    qtbot.wait(300)
    pl = w.viewport.plotter
    mesh = pl.renderer.actors["surface"].GetMapper().GetInput()
    open("/tmp/e13/go", "w").write("go")
    t = time.perf_counter()
    for i in range(int(os.environ.get("N", "300"))):
        mesh.GetPoints().Modified()
        pl.ren_win.Render()
    print("\nper render", (time.perf_counter() - t) / int(os.environ.get("N", "300")) * 1e3, "ms")
    os.remove("/tmp/e13/go")
