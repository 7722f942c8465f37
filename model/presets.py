"""The emotion presets (happy, sad, angry, surprised, disgusted, afraid) in ARKit's shape names with ``_L``/``_R``
sides, as the bundled sample face and ICT FaceKit name their shapes: a rig read from an OBJ folder without a
``presets.json`` of its own, or from a glTF, gets those of them whose every shape it has (``fitting_presets``), as
Maya's pose library offers a rig's poses. A rig's own ``presets.json`` is the whole list."""
from __future__ import annotations

EMOTIONS: dict[str, dict[str, float]] = {
    "happy": {"mouthSmile_L": 1.0, "mouthSmile_R": 1.0, "cheekSquint_L": 0.6, "cheekSquint_R": 0.6,
              "eyeSquint_L": 0.3, "eyeSquint_R": 0.3},
    "sad": {"browInnerUp_L": 0.9, "browInnerUp_R": 0.9, "mouthFrown_L": 0.8, "mouthFrown_R": 0.8,
            "eyeBlink_L": 0.2, "eyeBlink_R": 0.2, "mouthLowerDown_L": 0.2, "mouthLowerDown_R": 0.2},
    "angry": {"browDown_L": 1.0, "browDown_R": 1.0, "eyeSquint_L": 0.5, "eyeSquint_R": 0.5,
              "noseSneer_L": 0.4, "noseSneer_R": 0.4, "mouthFrown_L": 0.4, "mouthFrown_R": 0.4,
              "mouthClose": 0.2},
    "surprised": {"browInnerUp_L": 1.0, "browInnerUp_R": 1.0, "browOuterUp_L": 1.0, "browOuterUp_R": 1.0,
                  "eyeWide_L": 1.0, "eyeWide_R": 1.0, "jawOpen": 0.55, "mouthFunnel": 0.25},
    "disgusted": {"noseSneer_L": 1.0, "noseSneer_R": 1.0, "mouthUpperUp_L": 0.8, "mouthUpperUp_R": 0.8,
                  "browDown_L": 0.5, "browDown_R": 0.5, "eyeSquint_L": 0.4, "eyeSquint_R": 0.4,
                  "cheekSquint_L": 0.4, "cheekSquint_R": 0.4, "mouthFrown_L": 0.3, "mouthFrown_R": 0.3},
    "afraid": {"browInnerUp_L": 1.0, "browInnerUp_R": 1.0, "browOuterUp_L": 0.4, "browOuterUp_R": 0.4,
               "eyeWide_L": 1.0, "eyeWide_R": 1.0, "mouthStretch_L": 0.8, "mouthStretch_R": 0.8,
               "jawOpen": 0.2},
}


def fitting_presets(shape_names) -> dict[str, dict[str, float]]:
    """The emotion presets whose every shape is among ``shape_names`` (copies), in ``EMOTIONS``' order."""
    names = set(shape_names)
    return {p: dict(w) for p, w in EMOTIONS.items() if names.issuperset(w)}
