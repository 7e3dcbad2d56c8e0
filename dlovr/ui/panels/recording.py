"""The recording panel: start and stop a recording of the live simulation, then compile it (in a
thread), write the program beside the recording and show it as a list of macros
(:mod:`dlovr.ui.program_view`)."""

from __future__ import annotations

import datetime as _dt
import threading
import time
from pathlib import Path
from typing import Any

import viser

from dlovr.outputs import OutputError, write_output
from dlovr.recording import compile_noted
from dlovr.ui.app import App
from dlovr.ui.program_view import program_html


class RecordingPanel:
    """The "Recording" folder and the commands behind it (:meth:`App.start_recording`,
    :meth:`App.stop_recording`); they work without the GUI too (the server not started)."""

    def __init__(self, app: App) -> None:
        self.app = app
        self.compile_thread: threading.Thread | None = None
        self.started = 0.0  # time.monotonic() when the recording in progress started

    def build_controls(self, gui: viser.GuiApi) -> None:
        """The buttons, at the top of the panel, and the hotkey R that starts or stops a recording."""
        app = self.app
        self.rec_btn = gui.add_button("Start recording", icon=viser.Icon.PLAYER_RECORD, color="red",
                                      hint="Record the demonstration (key R)")
        self.stop_btn = gui.add_button("Stop recording", icon=viser.Icon.PLAYER_STOP, disabled=True,
                                       hint="Stop, save and compile the program (key R)")

        @self.rec_btn.on_click
        def _(_e: Any) -> None:
            self.start_safely()

        @self.stop_btn.on_click
        def _(_e: Any) -> None:
            app.stop_recording(wait=False)

        cmd = gui.add_command("Start / stop recording", hotkey="R")
        cmd.on_trigger(lambda _e: self.toggle())

    def build(self, gui: viser.GuiApi) -> None:
        """The folder with the last recording's file and program."""
        with gui.add_folder("Recording"):
            self.rec_md = gui.add_markdown(f"Recordings go to `{self.app.recordings_dir}/`")
            self.program_html = gui.add_html("")

    def toggle(self) -> None:
        """Start a recording, or stop the one in progress (the hotkey)."""
        if self.app.session.recorder is None:
            self.app.start_recording()
        else:
            self.app.stop_recording(wait=False)

    def forget(self) -> None:
        """Another scene: clear the last recording's note and program (they belong to the old scene)."""
        if self.app.server is not None:
            self.rec_md.content = f"Recordings go to `{self.app.recordings_dir}/`"
            self.program_html.content = ""

    def start(self, path: str | Path | None = None) -> Path:
        app = self.app
        out = app.session.start_recording(Path(path)) if path is not None else self._start_new()
        self.started = time.monotonic()
        if app.server is not None:
            self.rec_md.content = f"Recording to `{out}`"
            self.rec_btn.disabled = True
            self.stop_btn.disabled = False
        return out

    def _start_new(self) -> Path:
        """Record to a new file ``SCENE-YYYYmmdd-HHMMSS[-K].mcap`` in the recordings folder: created
        exclusively (another server's recording of the same second is never replaced: the next K)."""
        app = self.app
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        for k in range(1000):
            path = app.recordings_dir / f"{app.session.scene.name}-{stamp}{f'-{k}' if k else ''}.mcap"
            if path.exists():
                continue
            try:
                return app.session.start_recording(path)
            except OutputError:
                if not path.exists():  # not taken meanwhile: another problem (a full disk...)
                    raise
        raise OutputError(f"{app.recordings_dir}: 1000 recordings named {app.session.scene.name}-{stamp}")

    def start_safely(self) -> Path | None:
        """:meth:`start` for the button: a recording that cannot start (its folder not writable, the
        disk full) is said on the page and on stderr (``app.reporter``); None then."""
        app = self.app
        try:
            return app.start_recording()
        except (OSError, ValueError) as e:
            reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
            where = getattr(e, "filename", None) or app.recordings_dir
            line = f"cannot record to {where}: {reason}"
            report = getattr(app, "reporter", None)
            if report is not None:
                report("recording", line)
            if app.server is not None:
                self.rec_md.content = f"**Cannot record**: `{where}`: {reason}"
            return None

    def stop(self, *, wait: bool = True) -> Path | None:
        with self.app.lock:
            path = self.finish()
        if path is not None and wait and self.compile_thread is not None:
            self.compile_thread.join()
        return path

    def finish(self) -> Path | None:
        """Finish the recording in progress, if any, and start compiling it; the file or None."""
        app = self.app
        path = app.session.stop_recording()
        if path is None:
            return None
        app.last_recording = path
        if app.server is not None:
            self.rec_md.content = f"Saved `{path}`; compiling..."
            self.rec_btn.disabled = False
            self.stop_btn.disabled = True
        self.compile_thread = threading.Thread(
            target=self._compile, args=(path, app.session.scene.name), daemon=True
        )
        self.compile_thread.start()
        return path

    def _compile(self, path: Path, scene: str) -> None:
        """Compile the recording, write ``<stem>.program.json`` and ``.program.txt`` beside it (as
        ``dlovr compile`` names them) and show the program as a list of macros."""
        app = self.app
        view = ""
        try:
            prog, note = compile_noted(path)
            text = prog.listing()
            files: list[tuple[str, Path]] = [("recording", path)]
            try:
                jpath = path.with_name(f"{path.stem}.program.json")
                tpath = path.with_name(f"{path.stem}.program.txt")
                write_output(jpath, prog.dumps(), force=False)  # atomic; never over another file
                write_output(tpath, text, force=False)
                files += [("program", jpath), ("listing", tpath)]
                md = f"Saved `{path}` and its program"
            except (OSError, OutputError) as e:
                why = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
                md = f"Saved `{path}`; cannot write its program: {why}"
            if note:  # what the demonstrator can do better next time
                md += f"\n\n**Warning:** {note}."
            view = program_html(prog, files)
            # set last: the run panel offers the program once last_program changes, from its file
            app.program_text, app.last_program = text, prog
        except Exception as e:  # shown to the user, not raised in a worker thread
            app.program_text = ""
            app.last_program = None
            md = f"Saved `{path}`; compiling failed: {e}"
        if app.server is not None:
            if app.session.scene.name != scene:  # the scene was switched meanwhile: name the file only
                md, view = f"{md} (scene {scene})", ""
            self.rec_md.content = md
            self.program_html.content = view
