"""Per-shape textures in the application: which textures a rig has, the Texture panel, and the viewport's
texture kept blended with the pose (sliders, marker drags that solve, takes that play: every pose change).

The textures of a rig: the bundled sample's are generated (resources.sample_textures); a project lists its
own in its ``textures`` section; otherwise they are found by name beside the rig's files (model.textures).
Reading them and building the blend's bands runs off the GUI thread, once per rig, the first time a blend
mode is chosen; after that a pose change re-blends only the boxes of the shapes whose weights changed.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PySide6 import QtCore

from model.errors import RigInputError
from model.rig import Rig
from model.textures import (SECTION, TextureSet, display_split, files_from_section, find_texture_files,
                            load_texture_set, section_from_files, uv_problems)
from solvers.texture_blend import TextureBlender


def rig_textures(rig: Rig, sections: dict | None = None, project_path: str | Path | None = None
                 ) -> tuple[TextureSet | None, list[str]]:
    """The textures of ``rig`` (module docstring) and one sentence per problem met."""
    tex, problems, _ = _rig_textures(rig, sections, project_path)
    return tex, problems


def _rig_textures(rig: Rig, sections, project_path):
    """(texture set, problems, the files found by name beside the rig or None)."""
    from resources.sample_rig import SAMPLE_SOURCE
    if rig.source == SAMPLE_SOURCE:
        from resources.sample_textures import sample_textures
        neutral, shapes, keep = sample_textures()
        known = {k: v for k, v in shapes.items() if k in rig.shape_names}
        problems = uv_problems(rig)
        if rig.corners is None or rig.corners.uvs is None:
            return None, problems, None
        return TextureSet(neutral, known, keep, {}, problems, "generated (the bundled sample)"), problems, None
    section = (sections or {}).get(SECTION)
    found = None
    if section is not None:
        base = Path(project_path).parent if project_path is not None else Path.cwd()
        files, listed = files_from_section(section, base, rig.shape_names)
    else:
        files, listed = find_texture_files(rig), []
        found = None if files.empty else files
    tex, problems = load_texture_set(rig, files)
    return tex, listed + problems, found


def build_blender(tex: TextureSet, rig: Rig, mode: str, detail: str, masked: bool) -> TextureBlender:
    return TextureBlender(tex.neutral, tex.shape_list(rig.shape_names), keep=tex.keep if masked else None,
                          mode=mode, detail=detail)


def texture_weights(weights: np.ndarray, region_weights: np.ndarray | None = None) -> np.ndarray:
    """The weights a texture blends by: the pose's, or for a regional pose each shape's largest weight over the
    regions (a wrinkle shows where its shape is active in any region)."""
    return np.asarray(weights if region_weights is None else np.max(region_weights, axis=0), dtype=np.float64)


def render_texture(rig: Rig, weights: np.ndarray, rig_path, mode: str, detail: str, view: str = "shaded"):
    """(display split, uint8 image) for ``render --texture``; problems go to stderr, one line each; no usable
    texture raises RigInputError."""
    if view != "shaded":
        raise RigInputError(f"--texture {mode}: textures are drawn in the shaded view (not --view {view}).")
    sections, project = None, None
    if Path(rig_path).suffix.lower() == ".bsproj":
        from model.project import load_project
        sections, project = load_project(rig_path).sections, rig_path
    tex, problems = rig_textures(rig, sections, project)
    for p in problems:
        print(f"warning: {p}", file=sys.stderr)
    if tex is None:
        why = problems[-1] if problems else f"{rig_path}: no neutral texture (neutral.png) beside the rig."
        raise RigInputError(f"--texture {mode}: no texture to draw. {why}")
    blender = build_blender(tex, rig, mode, detail, masked=True)
    blender.set_weights(np.asarray(weights, dtype=np.float64))
    return display_split(rig), blender.image8


class TextureController(QtCore.QObject):
    textures_ready = QtCore.Signal()   # a rig's textures are loaded and shown (tests wait on it)

    def __init__(self, window, panel, dock) -> None:
        super().__init__(window)
        from app.background import BackgroundRunner
        self.window, self.panel, self.dock = window, panel, dock
        self.document, self.viewport = window.document, window.viewport
        self.runner = BackgroundRunner(self)
        self.textures: TextureSet | None = None
        self.blender: TextureBlender | None = None
        self.split = None
        self.problems: list[str] = []
        self._loaded_for = None    # the rig object the textures were read for
        self._names: list[str] = []   # its shape names then
        self._generation = 0
        d = self.document
        d.rig_changed.connect(self._on_rig_change)
        d.shapes_changed.connect(self._on_shapes_change)
        d.pose_changed.connect(self._on_pose_change)
        panel.mode_changed.connect(self._on_mode_change)
        panel.detail_changed.connect(self._on_mode_change)
        panel.mask_toggled.connect(self._on_mask_toggled)
        dock.visibilityChanged.connect(lambda on: self._show_bands() if on else None)

    @property
    def mode(self) -> str:
        return self.panel.current_mode()

    @property
    def loading(self) -> bool:
        return self.runner.busy

    # --- a new rig: textures are read when a mode needs them ------------------------------------------
    def _on_rig_change(self) -> None:
        self._generation += 1
        self.textures, self.blender, self.split, self._loaded_for = None, None, None, None
        self.problems = []
        self.panel.set_bands(None)
        self.panel.set_problems([])
        self.panel.set_dominant("")
        self.panel.set_source("not read yet (choose a blend)" if self.document.rig is not None else "No rig", False)
        if self.mode != "none":
            self._load()

    def _on_shapes_change(self) -> None:
        """Shapes added, removed or renamed: the blend is rebuilt for the new list (the texture shown stays until
        then); a corrective edit, which also reports the shapes, keeps the blend."""
        rig = self.document.rig
        if self._loaded_for is not None and rig is not None and self._names != list(rig.shape_names):
            self._generation += 1
            self._loaded_for = None
            self.blender = None
            if self.mode != "none":
                self._load()

    def _load(self) -> None:
        doc = self.document
        rig = doc.rig
        if rig is None or self._loaded_for is rig:
            return
        self._loaded_for = rig
        self._names = list(rig.shape_names)
        generation = self._generation
        sections = dict(doc.project.sections)
        path = doc.path
        mode, detail, masked = self.mode, self.panel.current_detail(), self.panel.mask.isChecked()
        self.panel.set_source("reading…", False)

        def job():
            tex, problems, found = _rig_textures(rig, sections, path)
            blender = build_blender(tex, rig, "band-pass" if mode == "none" else mode, detail, masked) if tex else None
            return generation, tex, problems, blender, display_split(rig) if tex else None, found

        self.runner.submit(job, self._loaded, self._failed)

    def _failed(self, message: str) -> None:
        self.problems = [message]
        self.panel.set_problems(self.problems)
        self.panel.set_source("none", False)

    def _loaded(self, result) -> None:
        generation, tex, problems, blender, split, found = result
        if generation != self._generation:
            return   # another rig came meanwhile
        if found is not None and tex is not None and SECTION not in self.document.project.sections:
            # textures found beside the rig's files: a project saved from it lists them (absolute paths), so
            # they come back wherever the project is saved; view state like the view and the take, no undo step
            self.document.project.sections[SECTION] = section_from_files(found)
        self.textures, self.problems, self.blender, self.split = tex, problems, blender, split
        self.panel.set_problems(problems)
        if tex is None:
            self.panel.set_source("none found beside the rig", False)
            if problems:
                self.window.show_status(problems[0], 10000)
            self.textures_ready.emit()
            return
        h, w = tex.neutral.shape[:2]
        self.panel.set_source(f"{len(tex.shapes)} shape textures + neutral, {w}x{h} ({tex.origin})",
                              tex.keep is not None)
        if problems:
            self.window.show_status(f"Textures: {problems[0]}", 10000)
        self._apply()
        self.textures_ready.emit()

    # --- blending --------------------------------------------------------------------------------------
    def _weights(self) -> np.ndarray:
        d = self.document
        return texture_weights(d.project.weights, d.region_weights)

    def _apply(self) -> None:
        """Show the blend for the current mode (or plain shading for 'none')."""
        if self.mode == "none" or self.blender is None:
            self.viewport.set_texture(None, None)
            self.panel.set_bands(None)
            self.panel.set_dominant("")
            return
        self.blender.set_mode(self.mode, self.panel.current_detail())
        self.blender.set_weights(self._weights())
        self.viewport.set_texture(self.split, self.blender.image8)
        self._show_bands()

    def _on_mode_change(self, _value=None) -> None:
        if self.mode != "none" and self.blender is None:
            self._load()
            return
        self._apply()

    def _on_mask_toggled(self, on: bool) -> None:
        if self.blender is None or self.textures is None:
            return
        self.blender.set_keep(self.textures.keep if on else None)
        if self.mode != "none":
            self.viewport.update_texture(self.blender.image8)
            self.window.request_render()
            self._show_bands()

    def _on_pose_change(self) -> None:
        if self.blender is None or self.mode == "none" or self.document.rig is None:
            return
        w = self._weights()
        if w.shape != (self.blender.n_shapes,):
            return   # shapes were added or removed: the next rig change rebuilds the textures
        boxes = self.blender.set_weights(w)
        if boxes:
            self.viewport.update_texture(self.blender.image8, boxes)
        self._show_bands()

    def _show_bands(self) -> None:
        if self.blender is None or self.mode == "none" or not self.dock.isVisible():
            return
        low, detail = self.blender.bands()
        self.panel.set_bands(self.blender.image, low, detail)
        if self.mode == "band-pass":
            k = self.blender.dominant()
            names = self.document.rig.shape_names
            self.panel.set_dominant({"neutral": "the neutral's",
                                     "dominant": names[k] if k >= 0 else "the neutral's",
                                     "regional": f"per region (strongest: {names[k]})" if k >= 0 else "the neutral's"}
                                    [self.panel.current_detail()])
        else:
            self.panel.set_dominant("all shapes, averaged by the weights")

    def shutdown(self) -> None:
        self.runner.shutdown()


def install(window) -> TextureController:
    """Plug the Texture dock into ``window`` (MainWindow's public add_dock); the window keeps the controller
    as ``window.textures``."""
    from app import settings as app_settings
    from widgets.texture_panel import TexturePanel
    panel = TexturePanel(window)
    dock = window.add_dock("Texture", panel, QtCore.Qt.RightDockWidgetArea, scroll=True)
    app_settings.remember(panel.mode, "texture/mode")
    app_settings.remember(panel.detail, "texture/detail")
    app_settings.remember(panel.mask, "texture/mask")
    panel._sync_enabled()
    return TextureController(window, panel, dock)
