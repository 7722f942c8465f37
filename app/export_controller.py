"""File ▸ Export Rig: the rig with its pose and an animation as glTF, USD or OBJ (``model.export.export_rig``,
the same function as the ``export`` command), written in the background so the window never freezes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.background import BackgroundRunner
from model.errors import RigInputError
from model.export import WeightAnimation, animation_from_timeline, check_export_space, export_rig

FILTERS = ("glTF binary (*.glb);;glTF (*.gltf);;USD (*.usd *.usda *.usdc);;OBJ, the posed surface (*.obj)")
UNITS = ("m", "cm", "mm")


class ExportDialog(QtWidgets.QDialog):
    """Which animation goes with the rig, in which units and with which axis up."""

    def __init__(self, animations: list[str], parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Export Rig")
        form = QtWidgets.QFormLayout(self)
        self.animation = QtWidgets.QComboBox()
        self.animation.addItems(["None (the current pose)"] + animations)
        self.animation.setToolTip("Keyframes are sampled at their frame rate; a solved or Live Link Face take at "
                                  "its own. Correctives become extra morph targets driven by their activation.")
        self.units = QtWidgets.QComboBox()
        self.units.addItems(["metres (glTF's unit)", "centimetres", "millimetres", "the rig's own units"])
        self.units.setToolTip("glTF and USD players expect metres; OBJ keeps the rig's units unless you choose")
        self.up = QtWidgets.QComboBox()
        self.up.addItems(["Y up (glTF, Maya, Unity)", "Z up (Blender, Unreal, 3ds Max)"])
        form.addRow("Animation", self.animation)
        form.addRow("Units", self.units)
        form.addRow("Up axis", self.up)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.Ok | QtWidgets.QDialogButtonBox.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)
        app_settings.remember(self.units, "export/units")
        app_settings.remember(self.up, "export/up")

    def choice(self) -> tuple[str | None, str | None, str]:
        anim = None if self.animation.currentIndex() == 0 else self.animation.currentText()
        units = (UNITS + (None,))[self.units.currentIndex()]
        return anim, units, "z" if self.up.currentIndex() == 1 else "y"


class ExportController(QtCore.QObject):
    exported = QtCore.Signal(str)    # the file written
    failed = QtCore.Signal(str)      # the sentence shown

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.runner = BackgroundRunner(self)
        window.add_action("file", "E&xport Rig (glTF, USD, OBJ)…", self.export_dialog, "Ctrl+Shift+X",
                          "Write the rig with its shapes, correctives, pose and an animation for other tools")

    # --- what there is to export ---------------------------------------------------------------------
    def animations(self) -> dict[str, object]:
        """Animation name -> a function building it (keyframes, the Mocap panel's solved or weight take)."""
        out = {}
        keys = self.window.keyframes
        if len(keys.timeline):
            rig = self.window.document.rig
            out[f"Keyframes ({len(keys.timeline)} keys, {keys.fps:g} fps)"] = (
                lambda: animation_from_timeline(keys.timeline, keys.fps, deltas=rig.deltas, blend=keys.blend))
        ws = self.window.mocap.workspace
        W = ws.playing_weights()
        if W is not None and len(W):
            rate = ws.rate
            out[f"Mocap take ({len(W)} frames, {rate:g} fps)"] = (
                lambda: WeightAnimation(times=np.arange(len(W)) / rate, weights=np.array(W), source="the take"))
        return out

    def current_weights(self) -> np.ndarray:
        """The pose shown, as one weight per shape (a regional pose: the global weights closest to it)."""
        doc = self.window.document
        if doc.region_weights is None:
            return doc.weights
        from solvers.surface_fit import global_weights_of_regional
        return global_weights_of_regional(doc.rig.deltas, doc.region_blend, doc.region_weights)

    # --- exporting ------------------------------------------------------------------------------------
    def export_dialog(self) -> None:
        doc = self.window.document
        if doc.project is None:
            return
        start = str(self.window.export_folder() / f"{doc.rig.name}.glb")
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self.window, "Export Rig", start, FILTERS)
        if not path:
            return
        if not Path(path).suffix:
            path += ".glb"
        self.window.remember_export_folder(path)
        anims = self.animations()
        dialog = ExportDialog(list(anims), self.window)
        if dialog.exec() != QtWidgets.QDialog.Accepted:
            return
        name, units, up = dialog.choice()
        self.export_to(path, name, units=units, up=up)

    def export_to(self, path: str | Path, animation: str | None = None, *, units: str | None = None,
                  up: str = "y") -> None:
        """Export in the background: the rig and pose are taken now (``Rig.snapshot``), so edits made meanwhile do
        not leak in. A file its disk has no room for is refused first (``model.export.check_export_space``, as
        ``export`` refuses it)."""
        doc = self.window.document
        try:   # not over a file the window has open (the rig's, the project, a .gltf's buffers), as `export` refuses
            self.window.check_export_over_inputs(path, rig=doc.rig)      # an OBJ's .mtl too
        except RigInputError as exc:
            self._failed(str(exc))
            return
        rig = doc.rig.snapshot()   # not a deep copy: 11 s of a frozen window for a 422k-vertex, 228-shape rig
        weights = self.current_weights()
        anim = self.animations()[animation]() if animation else None
        path = Path(path)
        self.window.show_status(f"Exporting {path.name}…", 0)
        def job():
            check_export_space(rig, path, anim.n_frames if anim is not None else 0, units=units, up=up)
            return export_rig(rig, path, weights, anim, units=units, up=up)
        self.runner.submit(job, lambda p: self._done(path, anim), self._failed)

    def _done(self, path: Path, anim) -> None:
        frames = f" with {anim.n_frames} animated frames" if anim is not None else ""
        self.window.show_status(f"Exported {path}{frames}")
        self.exported.emit(str(path))

    def _failed(self, message: str) -> None:
        self.window.show_error("Could not export", message)
        self.failed.emit(message)

    def shutdown(self) -> None:
        self.runner.shutdown()
