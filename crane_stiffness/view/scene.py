"""The crane as a ``foxglove.SceneUpdate`` (JSON encoding): overhead triangle, platform at its live pose with the
deflection exaggerated, the six wires coloured by tension (slack ones grey and dashed), the applied force as an arrow,
and, given a measured 6×6 compliance, the translational compliance ellipsoid at the platform.

Frame ``crane_view``: the paper's ``crane_base`` turned 180° about x (x, −y, −z), so z points up as 3D viewers
expect; the platform's rest centre is the origin and the overhead triangle is at z = h. The drawn platform is at
``scale ×`` its displacement and rotation (its deflection is tens of µm, invisible at true scale); the scale is
written in the scene. Pure numpy, no ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from crane_stiffness.model.geometry import WIRE_NAMES, CraneGeometry
from crane_stiffness.model.rotation import quaternion_to_matrix
from crane_stiffness.view import jsonschema as js

FRAME = 'crane_view'
#: crane_base → crane_view (180° about x).
_FLIP = np.diag([1.0, -1.0, -1.0])
#: A wire whose tension is at most this is drawn slack [N].
SLACK_TENSION_N = 1e-6
#: Arrow length per newton of applied force [m/N].
ARROW_M_PER_N = 0.02
#: The compliance ellipsoid is the platform centre's displacement under a force of this size in every direction,
#: drawn at the deflection scale: its radii are the translational compliance's principal values [m/N] times
#: ``COMPLIANCE_FORCE_N × deflection_scale`` (the scene's metadata ``compliance_scale``) [N].
COMPLIANCE_FORCE_N = 25.0
#: Points of each principal section of the ellipsoid (a LINE_LOOP).
ELLIPSE_POINTS = 48
ELLIPSOID_COLOR = {'r': 0.75, 'g': 0.1, 'b': 0.75, 'a': 1.0}

_Color = dict[str, float]


@dataclass(frozen=True)
class CraneState:
    """What the scene shows at one instant. ``position``: platform centre displacement in crane_base [m], shape
    (3,); ``orientation``: quaternion [x, y, z, w] of the platform in crane_base; ``tensions``: wire_1..wire_6 [N];
    ``force``: applied force in crane_base [N], shape (3,); ``stamp_s``: s."""

    position: Sequence[float]
    orientation: Sequence[float]
    tensions: Sequence[float]
    force: Sequence[float]
    stamp_s: float


def _vec(p: Any) -> dict[str, float]:
    return {'x': float(p[0]), 'y': float(p[1]), 'z': float(p[2])}


def _pose(position: Any = (0.0, 0.0, 0.0), quat: Any = (0.0, 0.0, 0.0, 1.0)) -> dict[str, Any]:
    return {'position': _vec(position), 'orientation': {'x': float(quat[0]), 'y': float(quat[1]),
                                                        'z': float(quat[2]), 'w': float(quat[3])}}


def _color(r: float, g: float, b: float, a: float = 1.0) -> _Color:
    return {'r': r, 'g': g, 'b': b, 'a': a}


def tension_color(tension: float, max_tension: float) -> _Color:
    """Blue (no tension) to red (``max_tension`` and above); grey when slack."""
    if not tension > SLACK_TENSION_N:
        return _color(0.55, 0.55, 0.55, 0.9)
    u = min(max(tension / max_tension, 0.0), 1.0) if max_tension > 0 else 1.0
    return _color(0.15 + 0.8 * u, 0.35 * (1.0 - abs(2 * u - 1)), 0.95 * (1.0 - u) + 0.05)


def _exaggerated(state: CraneState, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(centre, rotation matrix) of the drawn platform in crane_base: displacement and rotation angle × scale."""
    quat = np.asarray(state.orientation, dtype=float)
    if not np.all(np.isfinite(quat)) or np.linalg.norm(quat) == 0.0:
        quat = np.array([0.0, 0.0, 0.0, 1.0])
    quat = quat / np.linalg.norm(quat)
    if quat[3] < 0:
        quat = -quat
    angle = 2.0 * math.atan2(float(np.linalg.norm(quat[:3])), float(quat[3]))
    axis = quat[:3] / np.linalg.norm(quat[:3]) if angle > 0 else np.array([0.0, 0.0, 1.0])
    half = 0.5 * angle * scale
    scaled = np.r_[axis * math.sin(half), math.cos(half)]
    return np.asarray(state.position, dtype=float) * scale, quaternion_to_matrix(scaled)


def _dashes(a: np.ndarray, b: np.ndarray, count: int = 12) -> list[dict[str, float]]:
    """Points of a LINE_LIST drawing a→b as ``count`` dashes."""
    out = []
    for i in range(count):
        out += [_vec(a + (b - a) * (i / count)), _vec(a + (b - a) * ((i + 0.6) / count))]
    return out


def compliance_ellipsoid(compliance: Any, centre: Any, scale: float) -> list[dict[str, Any]]:
    """The compliance ellipsoid {C·f : |f| = 1} × ``scale`` around ``centre`` (crane_view, m) as three LINE_LOOPs,
    its principal sections (each in the plane of two principal axes). ``compliance``: the (3, 3) translational block
    of C = K⁻¹ in crane_base [m/N] (its symmetric part is drawn); no lines when it is not finite and positive
    definite (a fit too poor to have an ellipsoid)."""
    c = np.asarray(compliance, dtype=float)
    if c.shape != (3, 3) or not np.all(np.isfinite(c)):
        return []
    values, axes = np.linalg.eigh(_FLIP @ (0.5 * (c + c.T)) @ _FLIP.T)  # crane_view
    if not values[0] > 0.0:
        return []
    radii = values * scale
    t = np.linspace(0.0, 2.0 * math.pi, ELLIPSE_POINTS, endpoint=False)
    origin = np.asarray(centre, dtype=float)
    loops = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        points = origin + np.outer(np.cos(t), radii[i] * axes[:, i]) + np.outer(np.sin(t), radii[j] * axes[:, j])
        loops.append({'type': 1, 'pose': _pose(), 'thickness': 2.0, 'scale_invariant': True,
                      'points': [_vec(p) for p in points], 'color': dict(ELLIPSOID_COLOR), 'colors': [],
                      'indices': []})
    return loops


def scene_update(geometry: CraneGeometry, state: CraneState, scale: float,
                 compliance: Any = None) -> dict[str, Any]:
    """The ``foxglove.SceneUpdate`` of ``state`` (a dict for JSON); one entity ``crane`` whose metadata holds each
    wire's tension as published (``tension.wire_i``, repr of the float) and the scale. ``compliance``: the measured
    translational compliance (3, 3) [m/N], crane_base, or None: its ellipsoid (:func:`compliance_ellipsoid`) at
    the drawn platform centre, ``COMPLIANCE_FORCE_N × scale`` (metadata ``compliance_scale``), after the wires."""
    top = geometry.top_points @ _FLIP.T  # (6, 3) crane_view
    centre, rot = _exaggerated(state, scale)
    platform = (centre + geometry.platform_points @ rot.T) @ _FLIP.T
    tensions = [float(t) for t in state.tensions]
    max_tension = max([t for t in tensions if math.isfinite(t)] + [geometry.weight / 3.0])
    sec = int(math.floor(state.stamp_s)) if math.isfinite(state.stamp_s) else 0
    stamp = {'sec': sec, 'nsec': int((state.stamp_s - sec) * 1e9) if math.isfinite(state.stamp_s) else 0}
    overhead = top[[0, 2, 4]]  # A, B, C: wires 1, 3, 5 start at them (geometry.WIRE_ENDS)
    lines: list[dict[str, Any]] = [
        {'type': 1, 'pose': _pose(), 'thickness': 4.0, 'scale_invariant': True,
         'points': [_vec(p) for p in overhead], 'color': _color(0.2, 0.2, 0.2), 'colors': [], 'indices': []}]
    texts = []
    for i, name in enumerate(WIRE_NAMES):
        t = tensions[i] if i < len(tensions) else math.nan
        slack = not t > SLACK_TENSION_N
        points = (_dashes(top[i], platform[i]) if slack else [_vec(top[i]), _vec(platform[i])])
        lines.append({'type': 2, 'pose': _pose(), 'thickness': 1.5 if slack else 3.0, 'scale_invariant': True,
                      'points': points, 'color': tension_color(t, max_tension), 'colors': [], 'indices': []})
        middle = 0.5 * (top[i] + platform[i])
        texts.append({'pose': _pose(middle), 'billboard': True, 'font_size': 12.0, 'scale_invariant': True,
                      'color': _color(0.1, 0.1, 0.1), 'text': f'{name}: {"slack" if slack else f"{t:.2f} N"}'})
    corners = platform[[0, 2, 4]]  # D, E, F: wires 1, 3, 5 end at them (geometry.WIRE_ENDS)
    triangles = [{'pose': _pose(), 'points': [_vec(p) for p in corners], 'color': _color(0.25, 0.5, 0.85, 0.85),
                  'colors': [], 'indices': []}]
    arrows = []
    force = np.asarray(state.force, dtype=float) @ _FLIP.T
    magnitude = float(np.linalg.norm(force)) if np.all(np.isfinite(force)) else 0.0
    platform_centre = centre @ _FLIP.T
    if magnitude > 0.0:
        arrows.append({'pose': _pose(platform_centre, _quat_from_x(force / magnitude)),
                       'shaft_length': ARROW_M_PER_N * magnitude, 'shaft_diameter': 0.004,
                       'head_length': 0.015, 'head_diameter': 0.012, 'color': _color(0.9, 0.45, 0.0)})
        texts.append({'pose': _pose(platform_centre + force / magnitude * (ARROW_M_PER_N * magnitude + 0.02)),
                      'billboard': True, 'font_size': 14.0, 'scale_invariant': True,
                      'color': _color(0.9, 0.45, 0.0), 'text': f'F = {magnitude:.2f} N'})
    texts.append({'pose': _pose((0.0, 0.0, geometry.height + 0.05)), 'billboard': True, 'font_size': 14.0,
                  'scale_invariant': True, 'color': _color(0.1, 0.1, 0.1),
                  'text': f'deflection shown x{scale:g}'})
    metadata = [{'key': 'deflection_scale', 'value': repr(float(scale))}]
    if compliance is not None:
        ellipsoid_scale = COMPLIANCE_FORCE_N * scale
        loops = compliance_ellipsoid(compliance, platform_centre, ellipsoid_scale)
        if loops:
            lines += loops
            metadata += [{'key': 'compliance_scale', 'value': repr(float(ellipsoid_scale))},
                         {'key': 'compliance_force_n', 'value': repr(COMPLIANCE_FORCE_N)}]
            texts.append({'pose': _pose(platform_centre + np.array([0.0, 0.0, -0.04])), 'billboard': True,
                          'font_size': 12.0, 'scale_invariant': True, 'color': dict(ELLIPSOID_COLOR),
                          'text': f'compliance: {COMPLIANCE_FORCE_N:g} N x{scale:g}'})
    metadata += [{'key': f'tension.{name}', 'value': repr(tensions[i]) if i < len(tensions) else 'nan'}
                 for i, name in enumerate(WIRE_NAMES)]
    entity = {'timestamp': stamp, 'frame_id': FRAME, 'id': 'crane', 'lifetime': {'sec': 0, 'nsec': 0},
              'frame_locked': False, 'metadata': metadata, 'arrows': arrows, 'cubes': [], 'spheres': [],
              'cylinders': [], 'lines': lines, 'triangles': triangles, 'texts': texts, 'models': []}
    return {'deletions': [], 'entities': [entity]}


def _quat_from_x(direction: np.ndarray) -> np.ndarray:
    """Quaternion [x, y, z, w] turning +x onto the unit vector ``direction``."""
    x = np.array([1.0, 0.0, 0.0])
    c = float(np.dot(x, direction))
    if c < -0.999999:
        return np.array([0.0, 0.0, 1.0, 0.0])
    axis = np.cross(x, direction)
    quat = np.r_[axis, 1.0 + c]
    return quat / np.linalg.norm(quat)


_VEC3 = js.obj({'x': js.NUMBER, 'y': js.NUMBER, 'z': js.NUMBER})
_POSE = js.obj({'position': _VEC3, 'orientation': js.obj({k: js.NUMBER for k in 'xyzw'})})
_COLOR = js.obj({k: js.NUMBER for k in 'rgba'})
_TIME = js.obj({'sec': js.COUNT, 'nsec': js.COUNT})
_DURATION = js.obj({'sec': js.INTEGER, 'nsec': js.COUNT})
_LINE = js.obj({'type': js.enum(LINE_STRIP=0, LINE_LOOP=1, LINE_LIST=2), 'pose': _POSE, 'thickness': js.NUMBER,
                'scale_invariant': js.BOOLEAN, 'points': js.array(_VEC3), 'color': _COLOR,
                'colors': js.array(_COLOR), 'indices': js.array(js.COUNT)})
_TRIANGLES = js.obj({'pose': _POSE, 'points': js.array(_VEC3), 'color': _COLOR, 'colors': js.array(_COLOR),
                     'indices': js.array(js.COUNT)})
_ARROW = js.obj({'pose': _POSE, 'shaft_length': js.NUMBER, 'shaft_diameter': js.NUMBER, 'head_length': js.NUMBER,
                 'head_diameter': js.NUMBER, 'color': _COLOR})
_TEXT = js.obj({'pose': _POSE, 'billboard': js.BOOLEAN, 'font_size': js.NUMBER, 'scale_invariant': js.BOOLEAN,
                'color': _COLOR, 'text': js.STRING})
_SIZED = js.obj({'pose': _POSE, 'size': _VEC3, 'color': _COLOR})  # cubes and spheres (never sent here)
#: The JSON schema of ``foxglove.SceneUpdate`` as this module writes it: Foxglove's field names and types for the
#: primitives used (lines, triangles, arrows, texts; cubes, spheres, cylinders and models stay empty). The name is
#: what Foxglove and Lichtblick's 3D panel recognise; the fields are what they parse (see view.jsonschema).
SCENE_SCHEMA = js.obj({
    'deletions': js.array(js.obj({'timestamp': _TIME, 'type': js.enum(MATCHING_ID=0, ALL=1), 'id': js.STRING})),
    'entities': js.array(js.obj({
        'timestamp': _TIME, 'frame_id': js.STRING, 'id': js.STRING, 'lifetime': _DURATION,
        'frame_locked': js.BOOLEAN, 'metadata': js.array(js.obj({'key': js.STRING, 'value': js.STRING})),
        'arrows': js.array(_ARROW), 'cubes': js.array(_SIZED), 'spheres': js.array(_SIZED),
        'cylinders': js.array(js.obj({'pose': _POSE, 'size': _VEC3, 'bottom_scale': js.NUMBER,
                                      'top_scale': js.NUMBER, 'color': _COLOR})),
        'lines': js.array(_LINE), 'triangles': js.array(_TRIANGLES), 'texts': js.array(_TEXT),
        'models': js.array(js.obj({'pose': _POSE, 'scale': _VEC3, 'color': _COLOR, 'override_color': js.BOOLEAN,
                                   'url': js.STRING, 'media_type': js.STRING}))}))},
    'foxglove.SceneUpdate')
