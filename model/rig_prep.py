"""What the window derives from a rig it opens before it can show and pose it, computed with the load, off the GUI
thread (``app.loading.LoadWorker``): on a studio-scale rig these are passes over every shape's deltas (228 shapes x
106k vertices: 3 s; 422k vertices: four times that), and on the GUI thread they froze the window after the progress
dialog had closed.

- the display pose evaluator (``model.pose.PoseEvaluator``, float32: the deltas of the vertices that move, gathered);
- the shapes' reach: each vertex's largest displacement over the shapes, ``max_k ‖d_k(v)‖`` (Joshi et al. 2003, §4:
  the point mobility of ``solvers.damping``), which frames the camera on where the shapes act
  (``focus_vertices``) and damps marker drags (``solvers.damping.damping_gains``);
- the default view's faces (``model.parts.drawn_faces``: the helper shells left out): which of them have a back side
  no one can see (``solvers.mesh.hidden_back_faces`` on the neutral), which the viewport culls, a graph search over
  the faces, 0.17 s at 106k vertices and ~0.7 s at 422k; and their triangulation for the display's vertex normals
  (``solvers.normals.VertexNormals``), 0.25 s at 422k;
- the rig's triangles (``Rig.triangles``: the polygons' fans, which markers sit on), 0.04 s at 422k.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solvers.damping import point_mobility
from solvers.mesh import bounds, cell_layout, hidden_back_faces, reversed_faces
from solvers.normals import VertexNormals
from solvers.parallel import Background

from .pages import small_pages_for
from .parts import drawn_faces
from .pose import PoseEvaluator
from .rig import Rig

FACE_SHARE = 0.75   # the cameras frame where the shapes act if it is at most this share of the model (focus_vertices)


@dataclass
class DefaultView:
    """The faces the window's default view draws, prepared for the viewport (``widgets.viewport.set_surface``)."""
    faces: np.ndarray | None      # indices into the rig's faces, in order; None: all of them
    hidden_backs: np.ndarray      # (n,) bool over them: ``hidden_back_faces`` on the neutral
    normals: VertexNormals        # the display normals of a surface of just those faces
    layout: tuple[np.ndarray, np.ndarray] | None = None    # their ``cell_layout`` (the viewport's cells)
    # the faces among them whose back can show, and those faces reversed (``reversed_faces``): the backs' cells
    backs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def is_for(self, faces: np.ndarray | None, n_faces: int) -> bool:
        """Whether this is of the faces ``faces`` (None: all), ``n_faces`` polygons."""
        return len(self.hidden_backs) == n_faces and (
            faces is self.faces is None or (faces is not None and self.faces is not None
                                            and np.array_equal(faces, self.faces)))


@dataclass
class RigPrep:
    """``prepare_rig``'s results for ``rig`` (the same object: a preparation is used only for the rig it was made
    from, as it was when made)."""
    rig: Rig
    evaluator: PoseEvaluator
    reach: np.ndarray          # (V,) max_k ‖d_k(v)‖, zeros for a rig without shapes
    view: DefaultView | None = None
    triangles: np.ndarray | None = None   # (T, 3) ``rig.triangles()``

    def is_for(self, rig: Rig) -> bool:
        return self.rig is rig


def shape_reach(rig: Rig) -> np.ndarray:
    """(V,) each vertex's largest displacement over the rig's shapes (``solvers.damping.point_mobility``; zeros
    for a rig without shapes, whose deltas are (0, V, 3))."""
    return point_mobility(rig.deltas)


def focus_vertices(neutral: np.ndarray, reach: np.ndarray) -> np.ndarray | None:
    """The points a camera should frame: where the shapes act (the face) when that is a part inside a larger model,
    else None: the whole model, as posed (as Frame All frames it). ``reach`` (V,): each vertex's largest displacement
    over the shapes (``model.rig_prep.shape_reach``).

    A vertex counts when some shape moves it by at least a tenth of what the shapes typically move the most
    (the 99th percentile of each vertex's largest displacement): on ICT FaceKit a few shapes drag the scalp
    and neck by a fraction of a millimetre, and framing every vertex that moves at all showed a small head
    and shoulders instead of the face. Interior parts that move (teeth, tongue) lie inside the face's box.
    Those vertices are framed only when their box is at most ``FACE_SHARE`` of the model's box along every axis (ICT
    FaceKit's face: 54-58% of the head and shoulders): where the shapes act across most of the model along some axis
    (a glTF cube whose one side moves: its box is the whole cube's but flat), framing them alone cut the rest of the
    model out of the picture (half the cube)."""
    reach = np.asarray(reach, dtype=np.float64)
    if reach.size:
        moving = reach > 1e-6 * max(1.0, float(np.abs(neutral).max()))
        if moving.sum() >= 3:
            acts = reach >= 0.1 * float(np.percentile(reach[moving], 99))
            face = neutral[acts if acts.sum() >= 3 else moving]
            lo, hi = bounds(neutral)
            face_lo, face_hi = bounds(face)
            if np.all(face_hi - face_lo <= FACE_SHARE * (hi - lo)):
                return face
    return None


def framed_points(focus: np.ndarray | None, points: np.ndarray, marked: np.ndarray | None) -> np.ndarray | None:
    """What a camera frames in a map view: the face (``focus``, from ``focus_vertices``; None: the whole surface) and
    the vertices the map paints (``marked``: indices into ``points``, the surface as drawn), so that a segmentation's
    regions reaching past where the shapes act most are not cut off at the picture's edge (ICT FaceKit's forehead
    regions reach 2.4 cm above that box). The window's camera presets and ``render`` frame alike."""
    if focus is None or marked is None or not len(marked):
        return focus
    return np.concatenate([np.asarray(focus, dtype=np.float64).reshape(-1, 3),
                           np.asarray(points, dtype=np.float64).reshape(-1, 3)[np.asarray(marked)]])


def default_view(rig: Rig) -> DefaultView:
    """The default view's faces, their hidden back sides, their display normals' triangulation and their cells."""
    faces, counts, indices = drawn_faces(rig)
    return view_of(counts, indices, rig.n_vertices, hidden_back_faces(rig.neutral, counts, indices), faces)


def view_of(counts: np.ndarray, indices: np.ndarray, n_vertices: int, hidden: np.ndarray,
            faces: np.ndarray | None = None) -> DefaultView:
    """The ``DefaultView`` of the polygons (``counts``, ``indices``) of a surface of ``n_vertices`` points, whose
    hidden back sides ``hidden`` are known (``hidden_back_faces``); ``faces``: which of the rig's faces they are."""
    shown_backs = np.flatnonzero(~hidden)
    return DefaultView(faces, hidden, VertexNormals(counts, indices, n_vertices), layout=cell_layout(counts, indices),
                       backs=(shown_backs, *reversed_faces(counts, indices, shown_backs)))


def prepare_rig(rig: Rig) -> RigPrep:
    """The display evaluator, the shapes' reach, the default view (``DefaultView``) and the triangles of ``rig``
    (seconds on a studio rig: call it off the GUI thread). The evaluator's float32 copy of a studio rig's deltas is
    written once here: ordinary pages for it (``model.pages``)."""
    # the neutral's faces only: on another core meanwhile
    view = Background(lambda: (default_view(rig), rig.triangles()))
    with small_pages_for(rig.deltas.nbytes):
        evaluator, reach = PoseEvaluator(rig), shape_reach(rig)
    view, triangles = view.result()
    return RigPrep(rig=rig, evaluator=evaluator, reach=reach, view=view, triangles=triangles)
