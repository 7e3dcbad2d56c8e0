"""Camera framing (no viser): where to put a perspective camera so that a box fills the view, and how
much of the view a set of points covers from a given camera.

Frames: world frame, z up, metres. Cameras follow viser's convention: ``wxyz`` rotates camera
coordinates into the world (``P_world = R p_cam + position``), the camera looks along its +z axis,
x to the right and y down in the image; ``fov`` is the vertical field of view (rad) and ``aspect``
the image width over its height.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dlovr.transforms import quat_to_matrix

VIEW_DIRECTION = (0.55, -0.8, 0.45)
"""From the framed box's centre toward the camera (front right, from above)."""

FOV = math.radians(50.0)
"""Vertical field of view (rad) the UI frames with (viser's default, 75°, makes the scene look far)."""

FILL = 0.86
"""Fraction of the view's limiting half-extent that the framed box covers."""


def box_corners(lo: Sequence[float] | np.ndarray, hi: Sequence[float] | np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of the axis-aligned box ``lo``-``hi`` (m, world frame)."""
    lo_, hi_ = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool)
    return np.where(idx, hi_, lo_)


def _basis(direction: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, image-up, forward) unit vectors of a camera looking along ``-direction``."""
    f = -direction / np.linalg.norm(direction)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:  # looking straight along up: any right will do
        r = np.cross(f, np.array([0.0, 1.0, 0.0]))
    r /= np.linalg.norm(r)
    return r, np.cross(r, f), f


def frame_box(
    lo: Sequence[float] | np.ndarray,
    hi: Sequence[float] | np.ndarray,
    *,
    direction: Sequence[float] = VIEW_DIRECTION,
    fov: float = FOV,
    aspect: float = 1.0,
    fill: float = FILL,
    up: Sequence[float] = (0.0, 0.0, 1.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Camera ``(position, look_at)`` (m, world) looking along ``-direction`` at the box ``lo``-``hi``,
    as close as it can be with every corner inside ``fill`` of the view's half-extents.

    The distance is exact for the box's corners (not a bounding sphere), and the look-at point is
    shifted across the view so that the box's projection is centred.
    """
    corners = box_corners(lo, hi)
    r, u, f = _basis(np.asarray(direction, dtype=float), np.asarray(up, dtype=float))
    ty = math.tan(fov / 2.0) * fill
    tx = ty * max(aspect, 1e-3)
    look = corners.mean(axis=0)
    dist = 0.0
    for _ in range(4):  # centre the projection: move look_at across the view, then refit the distance
        rel = corners - look
        x, y, z = rel @ r, rel @ u, rel @ f
        # corner inside the view: |x| <= tx (z + d) and |y| <= ty (z + d)
        dist = float(np.max(np.maximum(np.abs(x) / tx, np.abs(y) / ty) - z))
        depth = z + dist
        sx, sy = x / depth, y / depth
        cx, cy = (sx.max() + sx.min()) / 2.0, (sy.max() + sy.min()) / 2.0
        if abs(cx) < 1e-4 * tx and abs(cy) < 1e-4 * ty:
            break
        look = look + dist * (cx * r + cy * u)
    dist = max(dist, 1e-3)
    return look - dist * f, look


def projected_extent(
    points: np.ndarray,
    position: Sequence[float] | np.ndarray,
    wxyz: Sequence[float] | np.ndarray,
    fov: float,
    aspect: float,
) -> tuple[float, float]:
    """Fractions (width, height) of the image that the projections of ``points`` (k, 3) span, clipped
    to the image; points behind the camera are ignored (0, 0 if none is in front)."""
    rot = quat_to_matrix(np.asarray(wxyz, dtype=float))
    cam = (np.asarray(points, dtype=float) - np.asarray(position, dtype=float)) @ rot  # = R^T (p - t)
    front = cam[:, 2] > 1e-9
    if not front.any():
        return 0.0, 0.0
    c = cam[front]
    ty = math.tan(fov / 2.0)
    nx = np.clip(c[:, 0] / c[:, 2] / (ty * aspect), -1.0, 1.0)
    ny = np.clip(c[:, 1] / c[:, 2] / ty, -1.0, 1.0)
    return float(nx.max() - nx.min()) / 2.0, float(ny.max() - ny.min()) / 2.0


CAMERA_KEY_SPEED = 0.3
"""How fast the camera keys fly (W/S forward and back, A/D sideways, Q/E down and up): this fraction
of the workspace's diagonal per second (viser's own 2 m/s flew out of a 1 m scene in half a second)."""


def camera_key_speed(lo: Sequence[float] | np.ndarray, hi: Sequence[float] | np.ndarray) -> float:
    """The camera keys' speed (m/s) for the workspace box ``lo``-``hi`` (m)."""
    return CAMERA_KEY_SPEED * max(float(np.linalg.norm(np.asarray(hi, float) - np.asarray(lo, float))), 0.05)


CAMERA_KEYS_JS = """(function(){if(window.__dlovrCam)return;window.__dlovrCam=1;var held={},last=0;
var K={KeyW:1,KeyA:1,KeyS:1,KeyD:1,KeyQ:1,KeyE:1};
function typing(e){var t=e.target;
return t&&(t.tagName==='INPUT'||t.tagName==='TEXTAREA'||t.isContentEditable);}
function tick(now){var c=window.__viserMutable&&window.__viserMutable.cameraControl;
var dt=Math.min(Math.max((now-last)/1000,0),0.25),v=(window.__dlovrCamSpeed||0.3)*dt;last=now;
if(c&&c.enabled){if(held.KeyA)c.truck(-v,0,false);if(held.KeyD)c.truck(v,0,false);
if(held.KeyW)c.forward(v,false);if(held.KeyS)c.forward(-v,false);
if(held.KeyQ)c.elevate(-v,false);if(held.KeyE)c.elevate(v,false);}
if(Object.keys(held).length)requestAnimationFrame(tick);else last=0;}
document.addEventListener('keydown',function(e){if(!K[e.code]||typing(e)||e.ctrlKey||e.metaKey||e.altKey)return;
e.stopPropagation();if(held[e.code])return;held[e.code]=1;
if(!last){last=performance.now();requestAnimationFrame(tick);}},true);
document.addEventListener('keyup',function(e){if(K[e.code])delete held[e.code];},true);
window.addEventListener('blur',function(){held={};});})()"""
"""The page's camera keys, in place of viser's (whose key-down handler never sees these keys: this
one, on the document's capture phase, stops them): the camera flies at ``window.__dlovrCamSpeed``
m/s (:func:`camera_key_speed`, set by the server for the scene shown) while a key is held, moving
viser's camera controls as viser's own keys do (the arrow keys, which turn, stay viser's)."""
