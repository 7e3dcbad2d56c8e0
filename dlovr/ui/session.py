"""The simulation session (no viser): one scene's simulator, contact tracker, optional recorder and
live timeline, shared by the real-time thread and the GUI callbacks under one lock."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.model.transitions import classify_step, format_classes
from dlovr.plausibility import monitor_of
from dlovr.recording import DemoRecorder
from dlovr.scene import Scene
from dlovr.sim import SimulationDiverged, Simulator
from dlovr.sim.tracker import ContactTracker
from dlovr.ui.drawing import point_classes, point_colors, situation_faces
from dlovr.ui.forces import ForceTrace
from dlovr.ui.timeline import Band, Snapshot, Timeline

CONTACT_FORCE_S = 0.1
"""Seconds over which the panel's contact normal force is averaged (exponentially)."""


class Session:
    """One scene's simulation with its contact tracker, optional recorder and live timeline.

    All methods take ``lock``; :meth:`advance` is what the real-time thread calls.
    """

    def __init__(self, scene: Scene, lock: threading.RLock):
        self.scene = scene
        self.lock = lock
        self.sim = Simulator(scene, track=True)
        self.tracker: ContactTracker = self.sim.tracker
        self.geometry = self.tracker.geometry
        self.recorder: DemoRecorder | None = None
        self.runner: Any = None  # a program run that takes the steps (dlovr.execution.engine.Engine)
        self.record = self.sim.record()
        self.state = self.tracker.update(self.record)
        self.forces = ForceTrace()  # the gripper force, mean of every 10 steps
        self.forces.append(self.record.time, self.record.gripper_force)
        self.timeline = Timeline(forces=self.forces)
        self._kept_seen = 0
        self._last_snap_t = -1.0
        self.note = ""
        self.plausibility = monitor_of(self.sim)
        self.contact_force = 0.0  # sum of the contact normal forces (N), averaged over CONTACT_FORCE_S
        self._class_cache: dict[Any, tuple[str, ...]] = {}
        self._format_cache: dict[Any, str] = {}
        self._faces_cache: dict[Any, dict[str, Any]] = {}
        self._snapshot()
        self.start_pose = self.gripper_pose()  # (m, world; wxyz): where "Back to start pose" goes

    @property
    def dt(self) -> float:
        return float(self.sim.model.opt.timestep)

    def last_class(self) -> str:
        for b in reversed(self.timeline.bands):
            if b.classes:
                return format_classes(b.classes)
        return ""

    def advance(
        self, n: int, target: tuple[np.ndarray, np.ndarray] | None, deadline: float | None = None
    ) -> int | None:
        """Step up to ``n`` times toward ``target``, stopping early (after at least one step) once
        ``time.perf_counter()`` reaches ``deadline``; the number of steps taken, or None (and the
        state restored) if the sim diverged. While a program runs (``runner``), it takes the steps
        and ``target`` is ignored."""
        done = 0
        with self.lock:
            if self.runner is not None and not self.runner.done:
                while done < n and not self.runner.done:
                    done += self.runner.advance(min(5, n - done))
                    if deadline is not None and time.perf_counter() >= deadline:
                        break
                self._timeline_update()
                return done
            sim = self.sim
            if target is not None:
                sim.set_target(target[0], target[1])
            for _ in range(n):
                if done and deadline is not None and time.perf_counter() >= deadline:
                    break
                good = sim.get_state()
                try:
                    rec = sim.step()
                except SimulationDiverged as e:
                    sim.set_state(good)
                    sim.set_target(
                        sim.data.mocap_pos[sim.built.mocap_id], sim.data.mocap_quat[sim.built.mocap_id]
                    )
                    self.record = sim.record()
                    self.note = f"simulation diverged ({e.reason}); gripper stopped, state restored"
                    return None
                self.took(rec)
                done += 1
            self._timeline_update()
            return done

    def took(self, rec: Any) -> None:
        """The bookkeeping of a step taken (by :meth:`advance` or by a program run): record it, keep
        its state and its gripper force. Called under ``lock``."""
        if self.recorder is not None:
            self.recorder.step(rec)
        self.record, self.state = rec, rec.state  # the simulator tracks the contacts (track=True)
        self.forces.add(rec.time, rec.gripper_force)
        for ep in self.plausibility.update(rec):  # shown in the state panel (docs/recordings.md)
            self.note = f"implausible simulation: {ep.text()}"
        a = min(1.0, self.dt / CONTACT_FORCE_S)  # the contact normal force, averaged over ~0.1 s
        self.contact_force += a * (float(sum(rec.state.forces)) - self.contact_force)

    def _timeline_update(self) -> None:
        kept = self.tracker.kept
        bands = self.timeline.bands
        grew = len(kept) > self._kept_seen
        start = max(0, min(len(bands), len(kept)) - 2)  # only the last one or two may change
        del bands[start:]
        for i in range(start, len(kept)):
            k = kept[i]
            classes = self._classes(kept[i - 1].situation, k.situation, k.through_free) if i else ()
            bands.append(Band(k.start, k.end, self._format(k.situation), classes, self._faces(k.situation)))
        self._kept_seen = len(kept)
        if grew or self.record.time - self._last_snap_t >= 0.1:
            self._snapshot()

    def _classes(self, a: Any, b: Any, through_free: bool = False) -> tuple[str, ...]:
        """Classes of the step ``a -> b`` (a flight when ``b`` was reached through free space)."""
        key = (a, b, through_free)
        if key not in self._class_cache:
            self._class_cache[key] = tuple(classify_step(a, b, through_free))
        return self._class_cache[key]

    def _faces(self, sit: Any) -> dict[str, Any]:
        if sit not in self._faces_cache:
            self._faces_cache[sit] = situation_faces(sit)
        return self._faces_cache[sit]

    def _format(self, sit: Any) -> str:
        if sit not in self._format_cache:
            self._format_cache[sit] = sit.format()
        return self._format_cache[sit]

    def _snapshot(self) -> None:
        r, st = self.record, self.state
        pts = np.asarray(r.points, dtype=float)
        self.timeline.snapshots.append(
            Snapshot(
                r.time,
                pts,
                point_colors(point_classes(st, len(pts))),
                r.gripper_pos.copy(),
                r.gripper_quat.copy(),
                st.discrete.format(),
                situation_faces(st.discrete),
            )
        )
        self._last_snap_t = r.time

    def restart_timeline(self) -> None:
        self.timeline = Timeline(forces=self.forces)
        self._kept_seen = 0
        self._last_snap_t = -1.0
        self._snapshot()

    def start_recording(self, path: Path) -> Path:
        with self.lock:
            if self.recorder is not None:
                return self.recorder.path
            path.parent.mkdir(parents=True, exist_ok=True)
            self.recorder = DemoRecorder(path, self.scene, self.sim, self.tracker)
            self.state = self.tracker.current or self.state
            self.restart_timeline()
            return self.recorder.path

    def stop_recording(self) -> Path | None:
        with self.lock:
            rec, self.recorder = self.recorder, None
            return rec.close() if rec is not None else None

    def gripper_pose(self) -> tuple[np.ndarray, np.ndarray]:
        with self.lock:
            d, mid = self.sim.data, self.sim.built.mocap_id
            return d.mocap_pos[mid].copy(), d.mocap_quat[mid].copy()
