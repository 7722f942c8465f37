"""The Texture panel: blend mode (band-pass, linear, none), whose detail band shows, the keep mask, and the
current blend's two bands as thumbnails. It shows state and emits requests; the app does the work."""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

MODE_LABELS = [("none", "None (plain shading)"), ("band-pass", "Band-pass (Joshi §5)"), ("linear", "Linear")]
DETAIL_LABELS = [("regional", "Per region: the strongest shape there"), ("dominant", "Dominant shape"),
                 ("neutral", "Neutral")]
THUMB = 108   # thumbnail side, pixels: three in a row fit the side docks at the default window size


def _pixmap(image8: np.ndarray) -> QtGui.QPixmap:
    a = np.ascontiguousarray(image8)
    h, w = a.shape[:2]
    return QtGui.QPixmap.fromImage(QtGui.QImage(a.data, w, h, 3 * w, QtGui.QImage.Format_RGB888).copy())


class TexturePanel(QtWidgets.QWidget):
    mode_changed = QtCore.Signal(str)      # 'none', 'band-pass' or 'linear'
    detail_changed = QtCore.Signal(str)    # 'regional', 'dominant' or 'neutral'
    mask_toggled = QtCore.Signal(bool)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        form = QtWidgets.QFormLayout()
        self.mode = QtWidgets.QComboBox()
        for key, label in MODE_LABELS:
            self.mode.addItem(label, key)
        self.mode.setToolTip("How the shapes' textures blend: band-pass keeps each wrinkle's full contrast (low "
                             "bands blended by the weights, the detail band from one shape); linear averages them")
        self.mode.currentIndexChanged.connect(lambda _: self.mode_changed.emit(self.mode.currentData()))
        form.addRow("Blend", self.mode)
        self.detail = QtWidgets.QComboBox()
        for key, label in DETAIL_LABELS:
            self.detail.addItem(label, key)
        self.detail.setToolTip("Band-pass: whose detail band (wrinkles, pores) shows")
        self.detail.currentIndexChanged.connect(lambda _: self.detail_changed.emit(self.detail.currentData()))
        form.addRow("Detail from", self.detail)
        self.mask = QtWidgets.QCheckBox("Keep hair, neck and ears (mask)")
        self.mask.setChecked(True)
        self.mask.setToolTip("Texels under the keep mask (texture_mask.png) always show the neutral's texture")
        self.mask.toggled.connect(self.mask_toggled)
        form.addRow(self.mask)
        self.source = QtWidgets.QLabel("No rig")
        self.source.setWordWrap(True)
        form.addRow("Textures", self.source)
        self.dominant = QtWidgets.QLabel("")
        form.addRow("Detail shown", self.dominant)
        self.bands = {}
        grid = QtWidgets.QGridLayout()
        for col, (key, title) in enumerate((("image", "Blend"), ("low", "Low band"), ("detail", "Detail band"))):
            label = QtWidgets.QLabel()
            label.setFixedSize(THUMB, THUMB)
            label.setFrameShape(QtWidgets.QFrame.Box)
            label.setToolTip({"image": "The blended texture the face shows",
                              "low": "Σ α_k L_k: the low bands blended by the weights",
                              "detail": "The detail band (grey is zero, contrast ×4)"}[key])
            grid.addWidget(QtWidgets.QLabel(title), 0, col)
            grid.addWidget(label, 1, col)
            self.bands[key] = label
        self.problems = QtWidgets.QLabel("")
        self.problems.setWordWrap(True)
        self.problems.setStyleSheet("color: #c96;")
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(form)
        lay.addLayout(grid)
        lay.addWidget(self.problems)
        lay.addStretch(1)
        self._sync_enabled()
        self.mode.currentIndexChanged.connect(lambda _: self._sync_enabled())

    def _sync_enabled(self) -> None:
        band = self.mode.currentData() == "band-pass"
        self.detail.setEnabled(band)

    # --- state the app sets ---------------------------------------------------------------------------
    def current_mode(self) -> str:
        return self.mode.currentData()

    def current_detail(self) -> str:
        return self.detail.currentData()

    def set_source(self, text: str, has_mask: bool) -> None:
        self.source.setText(text)
        self.mask.setEnabled(has_mask)

    def set_problems(self, problems: list[str]) -> None:
        shown = problems[:4] + ([f"… and {len(problems) - 4} more"] if len(problems) > 4 else [])
        self.problems.setText("\n".join(shown))

    def set_dominant(self, text: str) -> None:
        self.dominant.setText(text)

    def set_bands(self, image: np.ndarray | None, low: np.ndarray | None = None, detail: np.ndarray | None = None) -> None:
        """Thumbnails of the blend and its bands (float images in [0, 1], detail around 0); None clears them."""
        if image is None:
            for label in self.bands.values():
                label.clear()
            return
        step = max(1, image.shape[0] // THUMB)
        views = {"image": image[::step, ::step], "low": low[::step, ::step],
                 "detail": 0.5 + 4.0 * detail[::step, ::step]}
        for key, a in views.items():
            a8 = np.clip(a * 255.0 + 0.5, 0, 255).astype(np.uint8)
            self.bands[key].setPixmap(_pixmap(a8).scaled(THUMB, THUMB, QtCore.Qt.KeepAspectRatio,
                                                         QtCore.Qt.SmoothTransformation))
