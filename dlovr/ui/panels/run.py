"""The "Run program" panel: pick a compiled program for the current scene and watch it execute live.

The programs offered: the sample programs (``recordings/programs/`` of the repository and of the
recordings directory) that belong to the current scene (:func:`dlovr.execution.run.check_program_scene`),
and the program compiled from the last recording. A run restarts the scene at its start pose and
executes the program with the execution engine (:class:`dlovr.execution.engine.Engine`): the real-time
loop steps it (:meth:`dlovr.ui.session.Session.advance`), so the cable, the situation, the timeline and
a recording in progress follow it as they follow a demonstration. The program's list of macros
highlights the one running and marks those that ended; the force plot shows the current macro's
detector signal (1 = fires); at the end a result line says whether the goal was reached, or which
macro failed and why (:func:`dlovr.execution.scoring.score`).
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import viser

from dlovr.execution.demo_track import load_track
from dlovr.execution.engine import Engine
from dlovr.execution.executor import Event, ExecOptions
from dlovr.execution.run import check_program_scene, find_recording, not_found
from dlovr.execution.scoring import RunResult
from dlovr.model.program import Program, ProgramError
from dlovr.ui.app import App
from dlovr.ui.forces import ForceTrace
from dlovr.ui.program_view import program_html

SAMPLE_PROGRAMS = Path(__file__).resolve().parents[3] / "recordings" / "programs"
"""The repository's sample programs (one per built-in scene)."""

NO_PROGRAM: str = "(no program for this scene)"


class RunPanel:
    """The "Run program" folder and :meth:`run` behind it (works without the GUI too)."""

    def __init__(self, app: App) -> None:
        self.app = app
        self.runner: Engine | None = None
        self.program: Program | None = None
        self.signals: ForceTrace | None = None  # the detector signal (first component), 1 = fires
        self.outcomes: dict[int, str] = {}
        self.result = ""
        self.note = ""  # why the run does not follow its demonstration ("" when it does)
        self.choices: dict[str, Path] = {}
        self._shown: tuple[Any, ...] = ()
        self._seen: tuple[str, int] = ("", 0)  # (scene, last program) the choices were made for
        self._scene_shown = ""  # the scene whose run result is shown

    def build(self, gui: viser.GuiApi) -> None:
        with gui.add_folder("Run program"):
            self.choice = gui.add_dropdown("Program", (NO_PROGRAM,))
            self.detect = gui.add_dropdown("Detection", ("force", "oracle"), initial_value="force")
            self.run_btn = gui.add_button("Run program", icon=viser.Icon.PLAYER_PLAY)
            self.stop_btn = gui.add_button("Stop run", icon=viser.Icon.PLAYER_STOP, disabled=True)
            self.result_md = gui.add_markdown("")
            self.view = gui.add_html("")
        self.run_btn.on_click(lambda _e: self._run_clicked())
        self.stop_btn.on_click(lambda _e: self.cancel("stopped"))

        @self.choice.on_update
        def _(_e: Any) -> None:
            if self.runner is None:
                self.preview()

        self.refresh()

    # -- the programs of the scene -----------------------------------------------------------------

    def programs(self) -> dict[str, Path]:
        """Label -> program file, for the programs that belong to the current scene."""
        app = self.app
        scene = app.session.scene
        found: dict[str, Path] = {}
        last = app.last_recording
        cands: list[tuple[str, Path]] = []
        if last is not None:
            cands.append((f"last recording: {last.stem}", last.with_name(f"{last.stem}.program.json")))
        for folder, kind in ((app.recordings_dir / "programs", "program"), (SAMPLE_PROGRAMS, "sample")):
            if folder.is_dir():
                cands += [(f"{kind}: {p.name.removesuffix('.program.json')}", p)
                          for p in sorted(folder.glob("*.program.json"))]
        seen: set[Path] = set()
        for label, path in cands:
            key = path.resolve()
            if key in seen or not path.is_file():
                continue
            seen.add(key)
            try:
                check_program_scene(Program.load(path), scene)
            except (ProgramError, OSError):
                continue
            found[label] = path
        return found

    def refresh(self) -> None:
        """Offer the programs of the current scene (after a scene change or a new recording)."""
        self.choices = self.programs()
        self._seen = self._key()
        if self.app.server is None:
            return
        options = tuple(self.choices) or (NO_PROGRAM,)
        keep = self.choice.value if self.choice.value in options else options[0]
        self.choice.options = options
        self.choice.value = keep
        self.run_btn.disabled = not self.choices
        self.preview()

    def preview(self) -> None:
        """Show the macros of the program picked (no run): what *Run program* would execute. A run
        shown before (another scene's, or the last result) is forgotten."""
        if self.runner is not None:
            return
        path = self.choices.get(str(self.choice.value)) if self.app.server is not None else None
        try:
            program = Program.load(path) if path is not None else None
        except (ProgramError, OSError):
            program = None
        self.program, self.outcomes, self._shown = program, {}, ()
        if self.app.server is not None:
            if self._seen[0] != self._scene_shown:
                self.result = ""
                self.result_md.content = ""
            self._scene_shown = self._seen[0]
            self.view.content = "" if program is None else program_html(program)
            self._shown = (id(program), None, ())

    # -- running -----------------------------------------------------------------------------------

    def _key(self) -> tuple[str, int]:
        return self.app.session.scene.name, id(self.app.last_program)

    def _run_clicked(self) -> None:
        try:
            self.run()
        except (ProgramError, OSError, ValueError) as e:
            self._say(f"cannot run: {e}")

    def run(self, path: str | Path | None = None, detect: str | None = None) -> Engine:
        """Restart the scene and run the program ``path`` (default: the one picked); returns the run,
        which the real-time loop advances. A recording in progress goes on with the run."""
        app = self.app
        self.cancel(None)
        if path is None:
            if self.app.server is None or self.choice.value not in self.choices:
                raise ProgramError("no program picked")
            path = self.choices[self.choice.value]
        program = Program.load(path)
        check_program_scene(program, app.session.scene)
        track, self.note = demonstration(program)
        opts = ExecOptions(detect=detect or (self.detect.value if app.server is not None else "force"))
        recording = app.session.recorder is not None
        app.load(app.session.scene.path)
        if recording:
            app.start_recording()
        ses = app.session
        self.program, self.outcomes, self.result = program, {}, ""
        self.signals = ForceTrace()
        signals = self.signals

        def took(rec: Any) -> None:
            ses.took(rec)
            signals.add(rec.time, (runner.signal, 0.0, 0.0))

        with app.lock:
            runner = Engine(
                program, ses.sim, opts, track=track, scene=ses.scene, on_step=took, on_event=self._event
            )
            runner.start()
            self.runner = ses.runner = runner
        if app.server is not None:
            self.stop_btn.disabled = False
            note = f" ({html.escape(self.note)})" if self.note else ""
            what = f"**{html.escape(program.name)}** (detection {opts.detect}){note}"
            self.result_md.content = f"Running {what}..."
        self._shown = ()
        self.update()
        return runner

    def cancel(self, why: str | None = "stopped") -> None:
        """Stop the run in progress (``why`` shown as its result; None: say nothing)."""
        runner, self.runner = self.runner, None
        if runner is None:
            return
        with self.app.lock:
            if self.app.session.runner is runner:
                self.app.session.runner = None
        runner.cancel()
        if why is not None:
            self._say(f"run {why}")
            self.app.hold()

    def _event(self, ev: Event) -> None:
        """An executor event."""
        if ev.kind == "detected":
            self.outcomes[ev.macro] = "ok"
        elif ev.kind == "went_on":
            self.outcomes[ev.macro] = "went on"
        elif ev.kind == "failed" and ev.macro:
            self.outcomes[ev.macro] = "failed"

    def update(self) -> None:
        """Show the run's progress; finish it when it ended (the server calls this at ``PANEL_HZ``)."""
        app = self.app
        if self._seen != self._key() and self.runner is None:
            self.refresh()
        runner = self.runner
        if runner is not None and app.session.runner is not runner:  # the scene was reset meanwhile
            self.cancel("stopped: the scene was restarted")
            return
        if runner is not None and runner.done:
            self._finish(runner)
        elif runner is not None and app.server is not None:  # the gizmo follows the program's target
            with app.lock:
                p, q = app.session.sim.target_pos.copy(), app.session.sim.target_quat.copy()
            app.move_gizmo(p, q)
        self._show_program()

    def _finish(self, runner: Engine) -> None:
        app = self.app
        with app.lock:
            app.session.runner = None
        self.runner = None
        res = runner.result() if runner.error is None else None
        if not isinstance(res, RunResult):
            self._say(f"run ended: {runner.error}")
        else:
            goal = " & ".join(res.goal) or "N"
            if res.success:
                text = f"**Goal reached** ({goal}) at t = {res.sim_time:.2f} s"
            else:
                text = f"**Failed**: {res.reason}"
            note = f" ({html.escape(self.note)})" if self.note else ""
            self._say(f"{html.escape(res.program)} ({res.detect}): {text}{note}")
        app.hold()

    def _say(self, text: str) -> None:
        self.result = text
        if self.app.server is not None:
            self.result_md.content = text
            self.stop_btn.disabled = True

    def _show_program(self) -> None:
        prog, runner = self.program, self.runner
        if prog is None or self.app.server is None:
            return
        current = runner.macro if runner is not None else None
        state = (id(prog), current, tuple(sorted(self.outcomes.items())))
        if state == self._shown:
            return
        self._shown = state
        self.view.content = program_html(prog, current=current, outcomes=dict(self.outcomes))

    def signal_caption(self) -> str:
        """A line for the force plot about the detector signal while a program runs."""
        runner = self.runner
        if runner is None or not runner.macro:
            return ""
        seen = [f"{e.t:.2f} s (macro {e.macro})" for e in list(runner.events) if e.kind == "detected"]
        line = "detected: " + ", ".join(seen[-4:]) if seen else "nothing detected yet"
        if runner.opts.detect != "force":
            return f"macro {runner.macro}: detection by the contact tracker (oracle); {line}"
        return f"detector of macro {runner.macro} (orange): {runner.signal:.2f}, fires at 1 (dashed); {line}"


def demonstration(program: Program) -> tuple[Any, str]:
    """The track of the demonstration ``program`` was compiled from (its macros follow it), and ""; or
    None and why not, said with the run (another way of moving gives another result, as ``dlovr run``
    says too): its recording was not found, or cannot be read."""
    other = "the macros move along the program's poses"
    try:
        path = find_recording(program)
        if path is None:
            missing = f"{not_found(program)}: {other}"
            return None, missing if program.source else ""
        return load_track(path), ""
    except Exception as e:  # any unreadable demonstration: the program's own poses
        return None, f"its demonstration cannot be read ({str(e)[:120]}): {other}"
