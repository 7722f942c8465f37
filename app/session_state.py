"""What a saved project brings back besides the rig and the pose: the view (the Segmentation panel's view mode
and level, the timeline's time) and the take with its marker map. Stored in ``project.sections`` when the project
is saved, applied when it is opened; view state, not an edit (no undo step, the project stays unmodified).

``sections['view']``: ``{"view": "segmentation", "level": 1, "time": 1.25}`` (the time: the timeline's playhead).
``sections['take']``: ``{"path": "/takes/take.c3d", "map": {<marker map JSON>, "source": "..."}, "neutral_frames":
"A:B", "rate": 30.0}`` -- the map is stored whole, so an automatic map (no file) comes back too; the neutral frames
only when chosen; the rate only for a take whose file gives none.
"""
from __future__ import annotations

from pathlib import Path

from model.errors import RigInputError
from model.marker_map import MarkerMap
from model.take_data import given_rate

VIEWS = ("shaded", "deformation", "deformation-rgb", "segmentation")


def store(window) -> None:
    """Write the view and the take into the project's sections (before it is saved)."""
    sections = window.document.project.sections
    seg = window.segmentation
    sections["view"] = {"view": seg.view, "level": int(seg.level), "time": float(window.keyframes.time)}
    ws = window.mocap.workspace
    if ws.take_path is None:
        sections.pop("take", None)
        return
    take: dict = {"path": str(ws.take_path)}
    neutral = window.mocap.panel.settings().get("neutral_frames")
    if neutral:
        take["neutral_frames"] = neutral   # the actor's neutral chosen on the take (Use This Frame as Neutral)
    if ws.take is not None and not ws.take.rate_from_file:
        take["rate"] = float(ws.take.rate)   # given in the Mocap panel for a file that gives none
    if ws.marker_map is not None:
        take["map"] = dict(ws.marker_map.to_json(), source=ws.marker_map.source)
    sections["take"] = take


def restore(window) -> None:
    """Apply a just-opened project's view and take (after the controllers took the new rig); what is missing or
    no longer fits is said in the status bar."""
    project = window.document.project
    view = project.sections.get("view") or {}
    if isinstance(view, dict):
        level = view.get("level")
        if isinstance(level, int) and level >= 0:
            window.segmentation.set_level(level)
        if view.get("view") in VIEWS:
            window.segmentation_panel.set_view(view["view"])
        time = view.get("time")
        if isinstance(time, (int, float)) and not isinstance(time, bool):
            window.keyframes.show_time(float(time))   # where the playhead was (a new rig's timeline starts at 0)
    take = project.sections.get("take")
    if not isinstance(take, dict) or not isinstance(take.get("path"), str):
        return
    path = Path(take["path"])
    if not path.is_file():
        window.show_status(f"The project's take {path} is not there any more; load it again (Mocap panel).", 10000)
        return
    mocap = window.mocap
    rate = take.get("rate")
    try:
        rate = given_rate(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else None
    except RigInputError:
        rate = None
    if not mocap.load_take(path, rate):
        return
    neutral = take.get("neutral_frames")
    mocap.panel.set_neutral_frames(neutral[:40] if isinstance(neutral, str) else None)
    mm = take.get("map")
    if isinstance(mm, dict):
        try:
            marker_map = MarkerMap(markers=dict(mm.get("markers") or {}), rig_units=mm.get("rig_units", "cm"),
                                   take_units=mm.get("take_units"), source=str(mm.get("source") or ""))
        except (RigInputError, TypeError, ValueError) as exc:
            window.show_status(f"The project's marker map was not loaded: {exc}", 10000)
            return
        mocap.use_map(marker_map)
