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

The positions are not averaged but have their tremor taken out (:func:`remove_tremor`): an average
also rounds off the quick moves a person makes (lowering a cable into a hole in 0.1 s is as fast
as the tremor), and on the peg-in-hole demonstrations it stopped the drag over the groove's corner
2-2.6 mm short of where the hand went, out of a margin of 5-10 mm (docs/people.md). Tremor is close
to a sinusoid of slowly changing amplitude and phase (Riviere et al., the weighted-frequency Fourier
linear combiner that cancels it in hand-held surgical instruments), so each coordinate's tremor is
fitted as one: its frequency the strongest in :data:`TREMOR_BAND_HZ` of what the average takes out,
its amplitude and phase by least squares over a sliding :data:`FIT_S` s window, and subtracted.
That leaves as little tremor as the average and the quick moves as the hand made them.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

#: The moving average's window (s): one period of the slowest tremor (8 Hz) and a bit.
WINDOW_S = 0.1
#: Passes of the moving average (3: close to a Gaussian kernel).
PASSES = 3
#: A track whose median acceleration is above this (m/s^2) trembles: 0.3 mm of tremor at 8-12 Hz
#: accelerates by 0.5-1 m/s^2 most of the time; a script's legs at constant speed by 0 (and its
#: holds), a person's eased moves and drift by a few hundredths.
TREMOR_ACCEL = 0.1
#: Where the tremor's frequency is looked for (Hz): physiological tremor is 8-12 Hz, with margin.
TREMOR_BAND_HZ = (6.0, 14.0)
#: The step (Hz) of that search.
BAND_STEP_HZ = 0.1
#: The window (s) over which the tremor's amplitude and phase are fitted: three periods at 10 Hz.
FIT_S = 0.3


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
    a = _accelerations(t, pos)
    return 0.0 if a is None else float(np.median(np.sqrt((a * a).sum(axis=1))))


def _accelerations(t: np.ndarray, pos: np.ndarray) -> np.ndarray | None:
    """The second differences of the positions ``pos`` (k, 3) m at the evenly spaced times ``t`` (s)
    over the step squared: the acceleration (k - 2, 3) m/s^2 at each inner sample. None for fewer
    than 3 samples or times that do not increase."""
    p = np.asarray(pos, dtype=float)
    if len(p) < 3:
        return None
    dt = float(np.median(np.diff(np.asarray(t, dtype=float))))
    if dt <= 0:
        return None
    return (p[2:] - 2.0 * p[1:-1] + p[:-2]) / (dt * dt)


#: A commanded track whose position accelerates at more than this fraction of its samples was made
#: by a hand (:func:`made_by_hand`): the built-in scripts' corners are 0.1-0.3 % of theirs, a
#: person-like hand's drift and tremor 100 %, its pace and easing alone 74 %, its key jogging 4 %.
HAND_FRACTION = 0.01
#: The acceleration (m/s^2) above which a sample counts: a script's legs at constant speed show 1e-11
#: (rounding), a hand's slowest drift (1.5 mm at 0.05 Hz) 1e-4 and more.
HAND_ACCEL = 1e-5


def made_by_hand(t: np.ndarray, pos: np.ndarray) -> bool:
    """Was the commanded gripper track (times ``t`` s, evenly spaced; positions ``pos`` (k, 3) m,
    world) made by a hand rather than played by a machine? A script moves along straight legs at
    constant speed: its position accelerates only at the corners between legs, a few samples in
    thousands. A hand's accelerates at nearly every sample (drift, tremor, eased moves), a
    key-jogging one at every step. True when more than :data:`HAND_FRACTION` of the samples
    accelerate by more than :data:`HAND_ACCEL`. (Positions only: a script's turn at constant rate
    moves its quaternion's components along sinusoids.)"""
    a = _accelerations(t, pos)
    return a is not None and float(np.mean(np.abs(a).max(axis=1) > HAND_ACCEL)) > HAND_FRACTION


def _phasor(t: np.ndarray, hz: float) -> np.ndarray | None:
    """``exp(2 pi i hz t)`` at the evenly spaced times ``t`` (s), by repeated multiplication (no
    vectorised sine: the same bits on every processor); None where ``t`` is not evenly spaced."""
    dt = float(t[1] - t[0])
    if dt <= 0 or np.abs(np.diff(t) - dt).max() > 1e-6 * dt:
        return None
    step = np.full(len(t), cmath.exp(2j * math.pi * hz * dt))
    step[0] = cmath.exp(2j * math.pi * hz * float(t[0]))
    return np.cumprod(step)


def remove_tremor(t: np.ndarray, x: np.ndarray, window_s: float = WINDOW_S) -> np.ndarray:
    """``x`` (k, c) sampled at the evenly spaced times ``t`` (s) less, per column, its tremor: a
    sinusoid at the frequency in :data:`TREMOR_BAND_HZ` strongest in what :func:`moving_average`
    over ``window_s`` takes out of it, amplitude and phase fitted by least squares over a
    sliding :data:`FIT_S` s window (module docstring). Unevenly spaced times: the moving average."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(x, dtype=float).copy()
    n = samples(t, window_s)
    if len(t) < 3 * n or _phasor(t, 1.0) is None:
        return moving_average(y, n)
    m = samples(t, FIT_S)
    lo, hi = TREMOR_BAND_HZ
    grid = [lo + BAND_STEP_HZ * k for k in range(round((hi - lo) / BAND_STEP_HZ) + 1)]
    for c in range(y.shape[1]):
        h = y[:, c] - moving_average(y[:, c], n)
        power = [abs(np.cumsum(h * z)[-1]) if (z := _phasor(t, f)) is not None else 0.0 for f in grid]
        z = _phasor(t, grid[int(np.argmax(power))])
        if z is None:
            return moving_average(np.asarray(x, dtype=float), n)
        sn, cs = np.imag(z), np.real(z)
        ss, cc, sc = (moving_average(a, m, 1) for a in (sn * sn, cs * cs, sn * cs))
        hs, hc = moving_average(h * sn, m, 1), moving_average(h * cs, m, 1)
        det = ss * cc - sc * sc
        ok = det > 1e-9
        a = np.where(ok, (hs * cc - hc * sc) / np.where(ok, det, 1.0), 0.0)
        b = np.where(ok, (hc * ss - hs * sc) / np.where(ok, det, 1.0), 0.0)
        y[:, c] -= a * sn + b * cs
    return y


def smooth_poses(
    t: np.ndarray, pos: np.ndarray, quat: np.ndarray, window_s: float = WINDOW_S
) -> tuple[np.ndarray, np.ndarray]:
    """Positions (k, 3) m with their tremor taken out (:func:`remove_tremor`) and quaternions (k, 4)
    wxyz smoothed by :func:`moving_average` over ``window_s`` (made one hemisphere with their
    predecessor first, renormalised after)."""
    n = samples(t, window_s)
    q = np.array(quat, dtype=float)
    if len(q) > 1:
        flip = (q[1:] * q[:-1]).sum(axis=1) < 0
        sign = np.concatenate([[1.0], np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)])
        q = q * sign[:, None]
    qs = moving_average(q, n)
    qs = qs / np.sqrt((qs * qs).sum(axis=1))[:, None]
    return remove_tremor(t, pos, window_s), qs
