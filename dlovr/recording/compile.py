"""Compiling recordings into programs: one recording (:func:`compile_recording`, reading only its
contact-state and wrench channels) and batches of them with a content-hash cache (``dlovr compile``)."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.outputs import OutputError, write_output
from dlovr.recording.format import RecordingError, one_line
from dlovr.recording.reader import Recording, kept_states


def compile_recording(path: str | Path, hold: float | None = None) -> Any:
    """Compile a recording into a program (docs/model.md, section 6); reads only the contact-state and
    wrench channels (detection parameters derived from the wrench; defaults, marked, without it)."""
    return _compiled(path, hold)[0]


def compile_noted(path: str | Path) -> tuple[Any, str | None]:
    """:func:`compile_recording`, and what ``dlovr compile`` warns of its program besides an early
    end (:func:`margin_note`; None: nothing): what the browser shows a demonstrator."""
    prog, _, followed = _compiled(path)
    return prog, margin_note(prog, followed)


def margin_note(prog: Any, followed: tuple[Any, Any]) -> str | None:
    """The warning of ``prog``'s drags of the tip into an instability that no force ends and that its
    demonstration went on too little past (:func:`dlovr.model.margins.blind_margins` of the
    ``followed`` track: times s, positions m world); None for none, and for a program compiled from
    a trembling hand's track (``smoothing_s``): run along it, such a drag goes on past its
    transition by at least ``dlovr.execution.motion.DRAG_PAST_M``."""
    from dlovr.model.margins import blind_margins, margin_warning

    if prog.smoothing_s:
        return None
    return margin_warning(blind_margins(prog, *followed))


def _compiled(path: str | Path, hold: float | None = None) -> tuple[Any, str | None, tuple[Any, Any]]:
    """The program of a recording, why the recording ended early (its end marker says) or None, and
    the track the program follows (times s, positions m world: the commanded one, smoothed as the
    program is) for :func:`dlovr.model.margins.blind_margins`."""
    from dlovr.model.program import compile_program

    rec = Recording(path)
    states = kept_states(rec, hold)
    payloads = rec.states()
    track, wrench, smoothing, followed = compile_inputs(rec)
    prog = compile_program(states, track, name=Path(path).stem, source=Path(path).name, wrench=wrench)
    if smoothing:
        prog = _smoothed_program(prog, smoothing)
    prog = _with_goal_tolerance(prog, wrench)
    ended = payloads[-1].get("end_reason") if payloads and payloads[-1].get("end") else None
    return prog, ended, followed


def _with_goal_tolerance(prog: Any, wrench: Any) -> Any:
    """``prog`` with the goal check's tolerance its demonstration shows
    (:func:`dlovr.model.derivation.goal_tolerance_deg`; none without a wrench or goal contacts)."""
    from dataclasses import replace

    from dlovr.model.derivation import goal_tolerance_deg

    classed = prog.classed
    if wrench is None or not classed or not prog.goal:
        return prog
    return replace(prog, goal_tolerance_deg=goal_tolerance_deg(wrench, classed[-1].t))


def _smoothed_program(prog: Any, why: str) -> Any:
    """``prog`` marked as compiled from the smoothed track and wrench: ``smoothing_s``, ``smoothing``,
    and every derived detection parameter's text saying so."""
    from dataclasses import replace

    from dlovr.model.smoothing import PASSES, WINDOW_S

    note = f" (from the wrench averaged over {WINDOW_S:g} s, {PASSES} passes: the hand's tremor taken out)"

    def noted(texts: dict[str, str]) -> dict[str, str]:
        return {k: v + note if v.startswith("derived:") else v for k, v in texts.items()}

    macros = tuple(
        replace(m, detection=tuple(replace(d, derivation=noted(d.derivation)) for d in m.detection))
        for m in prog.macros
    )
    return replace(prog, macros=macros, smoothing_s=WINDOW_S, smoothing=why)


def compile_inputs(rec: Recording) -> tuple[Any, Any, str, tuple[Any, Any]]:
    """What a recording's program is compiled from besides its kept situations: the gripper's pose
    track (a ``PoseTrack``), the wrench (a ``WrenchSeries`` or None) and why they were smoothed ("":
    as recorded); and the track the program follows (times s, positions m world; see
    :func:`_intended`)."""
    from dlovr.model.program import PoseTrack

    payloads = rec.states()
    try:
        t = np.array([float(p["t"]) for p in payloads])
        pos = np.array([p.get("gripper_pos", [0.0, 0.0, 0.0]) for p in payloads], dtype=float)
        quat = np.array([p.get("gripper_quat", [1.0, 0.0, 0.0, 0.0]) for p in payloads], dtype=float)
        track = PoseTrack(t, pos.reshape(-1, 3), quat.reshape(-1, 4))
    except (KeyError, TypeError, ValueError) as e:
        why = f"bad gripper pose in a contact-state message: {one_line(e)}"
        raise RecordingError(f"{rec.path}: {why}") from None
    return _intended(rec, track, rec.wrench())


def _intended(rec: Recording, track: Any, wrench: Any) -> tuple[Any, Any, str, tuple[Any, Any]]:
    """The track and wrench to compile from, why they were smoothed ("" when not), and the track
    the program follows (times s, positions m world): a demonstration whose commanded track trembles
    (:func:`dlovr.model.smoothing.tremor_of`) is compiled from its commanded track and wrench
    smoothed (the motion meant, the force a detector will see following it), and follows that
    smoothed track; any other is compiled from its contact-state poses and its wrench as recorded,
    and follows its commanded track."""
    from dlovr.model import smoothing as sm
    from dlovr.model.derivation import WrenchSeries
    from dlovr.model.program import PoseTrack

    steps, pos, quat = rec.commands()
    t = np.asarray(steps, dtype=float) * rec.dt
    tremor = sm.tremor_of(t, pos)
    if tremor <= sm.TREMOR_ACCEL:
        return track, wrench, "", (t, pos)
    spos, squat = sm.smooth_poses(t, pos, quat)
    why = (
        f"the commanded track trembles (median acceleration {tremor:.2f} m/s^2, above "
        f"{sm.TREMOR_ACCEL:g}): "
        f"motions and the executor's path are the track with its tremor taken out (per coordinate a "
        f"sinusoid of {sm.TREMOR_BAND_HZ[0]:g}-{sm.TREMOR_BAND_HZ[1]:g} Hz fitted over {sm.FIT_S:g} s "
        f"windows and subtracted; the orientation averaged over {sm.WINDOW_S:g} s, {sm.PASSES} passes)"
    )
    if wrench is not None and len(wrench.t):
        n = sm.samples(wrench.t, sm.WINDOW_S)
        force, torque = sm.moving_average(wrench.force, n), sm.moving_average(wrench.torque, n)
        wrench = WrenchSeries(wrench.t, force, torque)
        why += ", detection parameters derived from the wrench averaged the same way"
    return PoseTrack(t, spos, squat), wrench, why, (t, spos)


# --------------------------------------------------------------------------------------------------
# Batch compilation
# --------------------------------------------------------------------------------------------------

CACHE_NAME = ".dlovr-compile-cache.json"


@dataclass(frozen=True)
class CompileResult:
    """Outcome for one recording: ``error`` is None on success; ``skipped`` when unchanged;
    ``warning``: why the recording ended early (a diverged simulation), its program being partial, and
    the macros no force shows that its demonstration went on too little past (docs/programs.md)."""

    path: str
    json_path: str | None
    macros: int = 0
    risky: int = 0
    skipped: bool = False
    error: str | None = None
    warning: str | None = None


def find_recordings(inputs: Sequence[str | Path], in_order: bool = False) -> list[Path]:
    """Recordings named by files or found (``*.mcap``, recursively) in directories, sorted, unique;
    ``in_order``: in the order given instead (a directory's sorted), each once, first place kept."""
    found: list[Path] = []
    for i in inputs:
        p = Path(i)
        found.extend(sorted(q for q in p.rglob("*.mcap") if q.is_file()) if p.is_dir() else [p])
    return list(dict.fromkeys(found)) if in_order else sorted(set(found))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def program_paths(path: str | Path, out_dir: str | Path | None) -> tuple[Path, Path]:
    """Where a recording's program goes: ``<stem>.program.json`` and ``.program.txt`` in ``out_dir``
    (default: beside the recording)."""
    p = Path(path)
    out = Path(out_dir) if out_dir else p.parent
    return out / f"{p.stem}.program.json", out / f"{p.stem}.program.txt"


def check_unique_outputs(paths: Sequence[Path], out_dir: str | Path | None) -> list[Path]:
    """The recordings without duplicates (the same file named twice counts once); raises
    :class:`RecordingError` naming both inputs when two different recordings would write the same
    program (same file name, one output folder)."""
    seen: dict[Path, Path] = {}
    files: set[Path] = set()
    out = []
    for p in paths:
        real = p.resolve()
        if real in files:
            continue
        files.add(real)
        dst = program_paths(p, out_dir)[0].resolve()
        if dst in seen:
            raise RecordingError(
                f"{seen[dst]} and {p} would both be compiled to {program_paths(p, out_dir)[0]}: "
                "compile them into different -o folders (or without -o, beside each)"
            )
        seen[dst] = p
        out.append(p)
    return out


def for_sensor_noise(prog: Any, sigma: float) -> Any:
    """``prog`` with every detection set for a sensor of white noise ``sigma`` N
    (:func:`dlovr.model.detection.for_sensor`; the simulation's 2 ms samples)."""
    from dataclasses import replace

    from dlovr.model.detection import for_sensor

    macros = []
    for m in prog.macros:
        dets = []
        for d in m.detection:
            params, texts = for_sensor(d.cls, d.params, sigma)
            dets.append(replace(d, params=params, derivation={**d.derivation, **texts}))
        macros.append(replace(m, detection=tuple(dets)))
    return replace(prog, macros=tuple(macros))


def _cache_key(digest: str, sensor_noise: float | None, calibrated: bool = False) -> str:
    """What the compile cache keeps of a recording: its content hash, the sensor noise its program
    was set for (a program for a sensor is not the plain one) and whether it was calibrated."""
    key = f"{digest} sensor_noise={sensor_noise!r}" if sensor_noise else digest
    return key + " calibrated" if calibrated else key


def _file_sha256(path: Path) -> str | None:
    """The sha256 of a file, None when it cannot be read."""
    try:
        return _sha256(path)
    except OSError:
        return None


def _cache_entry(
    recording: Path, jpath: Path, tpath: Path, sensor_noise: float | None, calibrated: bool = False
) -> dict[str, Any]:
    """The compile cache's entry of a recording just compiled: what it was compiled from (its
    :func:`_cache_key`) and the hashes of the two program files written (so that a later compile
    knows them for its own: it replaces them without --force, unlike a file edited since)."""
    return {
        "recording": _cache_key(_sha256(recording), sensor_noise, calibrated),
        "json": _file_sha256(jpath),
        "txt": _file_sha256(tpath),
    }


def _replaceable(entry: Any, jpath: Path, tpath: Path) -> Path | None:
    """The first of the existing program files that compile may not replace without --force (not
    the file its cache ``entry`` says it wrote there: edited since, or written by something else),
    else None."""
    known = entry if isinstance(entry, dict) else {}
    for key, f in (("json", jpath), ("txt", tpath)):
        if os.path.lexists(f) and (known.get(key) is None or _file_sha256(f) != known.get(key)):
            return f
    return None


#: A program's calibration in simulation (``dlovr.execution.calibration.calibrate_recording``: the
#: program and its recording in, the program calibrated out), which the recording layer cannot import.
Calibrate = Callable[[Any, Path], Any]


def compile_one(
    path: str, out_dir: str | None, force: bool = False, sensor_noise: float | None = None,
    calibrate: Calibrate | None = None,
) -> CompileResult:
    """Compile one recording to ``<stem>.program.json`` and ``.program.txt`` (a worker's job), its
    detections calibrated in simulation by ``calibrate`` when given (``dlovr compile --calibrate``),
    then set for ``sensor_noise`` N of sensor noise when given (:func:`for_sensor_noise`). Its
    ``warning`` says why the recording ended early, and which macros no force shows whose
    demonstration went on too little past them (:func:`margin_note`)."""
    p = Path(path)
    if p.exists() and not p.is_file():  # a device (/dev/zero) or a pipe: hashing it would never end
        why = "not a regular file (a device or a pipe), not a recording"
        return CompileResult(str(p), None, error=f"{p}: {why}")
    try:
        digest = _sha256(p)
    except OSError as e:
        return CompileResult(str(p), None, error=f"{p}: cannot read: {e.strerror}")
    jpath, tpath = program_paths(p, out_dir)
    out = jpath.parent
    cache_file = out / CACHE_NAME
    entry: Any = None
    try:
        cache = json.loads(cache_file.read_text()) if cache_file.is_file() else {}
        entry = cache.get(p.name)
        made_from = entry.get("recording") if isinstance(entry, dict) else entry  # a string: an older cache
        fresh = made_from == _cache_key(digest, sensor_noise, calibrate is not None)
        if not force and fresh and jpath.is_file() and tpath.is_file():
            s = json.loads(jpath.read_text()).get("summary", {})
            return CompileResult(str(p), str(jpath), s.get("macros", 0), s.get("risky", 0), skipped=True)
    except (OSError, ValueError, AttributeError):
        pass  # no usable cache or program: compile again
    kept = None if force else _replaceable(entry, jpath, tpath)
    if kept is not None:
        why = "exists and is not the program compiled there before (edited since, or not compiled by dlovr)"
        return CompileResult(str(p), None, error=f"{kept}: {why}; give --force to overwrite it")
    try:
        prog, ended, followed = _compiled(p)
    except RecordingError as e:
        return CompileResult(str(p), None, error=str(e))
    if calibrate is not None:
        prog = calibrate(prog, p)
    if sensor_noise:
        prog = for_sensor_noise(prog, sensor_noise)
    try:  # atomic; a file that appeared meanwhile (another writer's) is kept, unless --force
        write_output(jpath, prog.dumps(), force=force or os.path.lexists(jpath))  # checked: ours
        write_output(tpath, prog.listing(), force=force or os.path.lexists(tpath))
    except OutputError as e:
        return CompileResult(str(p), None, error=str(e))
    notes = [f"the recording ends early ({ended}): its program is partial"] if ended else []
    margins = margin_note(prog, followed)  # of the program as it runs: calibrated, for the sensor
    notes += [margins] if margins else []
    warning = f"{p}: {'; '.join(notes)}" if notes else None
    return CompileResult(str(p), str(jpath), prog.summary["macros"], prog.summary["risky"], warning=warning)


def record_compiled(
    results: Sequence[CompileResult], out_dir: str | None, sensor_noise: float | None = None,
    calibrated: bool = False,
) -> None:
    """Remember what the recordings just compiled were compiled from (content hash, sensor noise) and
    the hashes of the program files written (in the parent process; :func:`_cache_entry`). A skipped
    recording's entry stays as it was (its program may have been edited since: not ours to replace)."""
    by_dir: dict[Path, dict[str, Any]] = {}
    for r in results:
        if r.error is None and r.json_path is not None and not r.skipped:
            jpath, tpath = program_paths(r.path, Path(r.json_path).parent)
            by_dir.setdefault(jpath.parent, {})[Path(r.path).name] = _cache_entry(
                Path(r.path), jpath, tpath, sensor_noise, calibrated
            )
    for d, entries in by_dir.items():
        f = d / CACHE_NAME
        try:
            cache = json.loads(f.read_text()) if f.is_file() else {}
        except (OSError, ValueError):
            cache = {}
        cache = {**(cache if isinstance(cache, dict) else {}), **entries}
        try:  # a cache that cannot be written only means compiling again next time
            write_output(f, json.dumps(dict(sorted(cache.items())), indent=1) + "\n", force=True)
        except OutputError:
            pass
