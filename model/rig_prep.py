"""What the window derives from a rig it opens before it can show and pose it, computed with the load, off the GUI
thread (``app.loading.LoadWorker``): on a studio-scale rig these are passes over every shape's deltas (228 shapes x
106k vertices: 3 s; 422k vertices: four times that), and on the GUI thread they froze the window after the progress
dialog had closed.

- the display pose evaluator (``model.pose.PoseEvaluator``, float32: the deltas of the vertices that move, gathered);
- the shapes' reach: each vertex's largest displacement over the shapes, ``max_k ‖d_k(v)‖`` (Joshi et al. 2003, §4:
  the point mobility of ``solvers.damping``), which frames the camera on where the shapes act
  (``widgets.scene.focus_vertices``) and damps marker drags (``solvers.damping.damping_gains``);
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
from solvers.mesh import cell_layout, hidden_back_faces, reversed_faces
from solvers.normals import VertexNormals
from solvers.parallel import Background

from .pages import small_pages_for
from .parts import drawn_faces
from .pose import PoseEvaluator
from .rig import Rig


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
