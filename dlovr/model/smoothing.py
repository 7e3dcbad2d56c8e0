"""The intended motion of a trembling hand: the demonstrated track and wrench with the tremor taken out.

Pure numpy, no BLAS (the smoothed track feeds the simulator: the same bits on every processor). A
person's hand adds physiological tremor of a few tenths of a millimetre at 8-12 Hz to what it means
to do (docs/people.md). The program should repeat the meant motion, and its detection thresholds
should come from the force a detector will see when the gripper follows that motion, not from the
tremor's force ripple. So, where a demonstration trembles (:func:`tremor_of` above
:data:`TREMOR_ACCEL`), the compiler takes the track and the wrench through :func:`moving_average`:
:data:`PASSES` passes of a centred moving average over :data:`WINDOW_S` s, which attenuates 8 Hz by
a factor of 75 and more above it, and a 1 Hz drift (what the person meant, as far as anyone can tell)
by 5 %. A scripted track (straight legs at constant speed) has no tremor and is left as it is.
"""

from __future__ import annotations

import numpy as np

#: The moving average's window (s): one period of the slowest tremor (8 Hz) and a bit.
WINDOW_S = 0.1
#: Passes of the moving average (3: close to a Gaussian kernel).
PASSES = 3
#: A track whose median acceleration is above this (m/s^2) trembles: 0.3 mm of tremor at 8-12 Hz
#: accelerates by 0.5-1 m/s^2 most of the time; a script's legs at constant speed by 0 (and its
#: holds), a person's eased moves and drift by a few hundredths.
TREMOR_ACCEL = 0.1


def moving_average(x: np.ndarray, n: int, passes: int = PASSES) -> np.ndarray:
    """``x`` (k, ...) averaged along its first axis over ``n`` samples (centred when ``n`` is odd),
    ``passes`` times;
    the ends are padded with the first and last sample (a track that starts and ends at rest)."""
    y = np.asarray(x, dtype=float)
    if n <= 1 or len(y) == 0:
        return y.copy()
    h = n // 2
    for _ in range(passes):
        pad = np.concatenate([np.repeat(y[:1], h, axis=0), y, np.repeat(y[-1:], n - 1 - h, axis=0)])
        c = np.concatenate([np.zeros((1, *y.shape[1:])), np.cumsum(pad, axis=0)])
        y = (c[n:] - c[:-n]) / n
    return y


def samples(t: np.ndarray, window_s: float) -> int:
    """How many samples of the series at times ``t`` (s) span ``window_s``: an odd number (the
    average is centred on its sample, no lag), at least 1."""
    if len(t) < 2:
        return 1
    dt = float(np.median(np.diff(np.asarray(t, dtype=float))))
    return 2 * (round(window_s / dt) // 2) + 1 if dt > 0 else 1


def tremor_of(t: np.ndarray, pos: np.ndarray) -> float:
    """The median acceleration (m/s^2) of the positions ``pos`` (k, 3) sampled at times ``t`` (s,
    evenly spaced): tenths of m/s^2 and more for a trembling hand, 0 for straight legs at constant
    speed (their corners are single samples)."""
    p = np.asarray(pos, dtype=float)
    if len(p) < 3:
        return 0.0
    dt = float(np.median(np.diff(np.asarray(t, dtype=float))))
    if dt <= 0:
        return 0.0
    a = (p[2:] - 2.0 * p[1:-1] + p[:-2]) / (dt * dt)
    return float(np.median(np.sqrt((a * a).sum(axis=1))))


def smooth_poses(
    t: np.ndarray, pos: np.ndarray, quat: np.ndarray, window_s: float = WINDOW_S
) -> tuple[np.ndarray, np.ndarray]:
    """Positions (k, 3) m and quaternions (k, 4) wxyz smoothed by :func:`moving_average` (the
    quaternions made one hemisphere with their predecessor first, renormalised after)."""
    n = samples(t, window_s)
    q = np.array(quat, dtype=float)
    if len(q) > 1:
        flip = (q[1:] * q[:-1]).sum(axis=1) < 0
        sign = np.concatenate([[1.0], np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)])
        q = q * sign[:, None]
    qs = moving_average(q, n)
    qs = qs / np.sqrt((qs * qs).sum(axis=1))[:, None]
    return moving_average(pos, n), qs
