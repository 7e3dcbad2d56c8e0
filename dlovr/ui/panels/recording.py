"""The recording panel: start and stop a recording of the live simulation, then compile it (in a
thread) and show its program."""

from __future__ import annotations

import datetime as _dt
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import viser

from dlovr.recording import compile_recording

if TYPE_CHECKING:
    from dlovr.ui.server import DemoServer


class RecordingPanel:
    """The "Recording" folder and the commands behind it (:meth:`DemoServer.start_recording`,
    :meth:`DemoServer.stop_recording`); they work without the GUI too (the server not started)."""

    def __init__(self, app: DemoServer) -> None:
        self.app = app
        self.compile_thread: threading.Thread | None = None

    def build(self, gui: viser.GuiApi) -> None:
        app = self.app
        with gui.add_folder("Recording"):
            self.rec_btn = gui.add_button("Start recording", icon=viser.Icon.PLAYER_RECORD)
            self.stop_btn = gui.add_button("Stop recording", icon=viser.Icon.PLAYER_STOP, disabled=True)
            self.rec_md = gui.add_markdown(f"Recordings go to `{app.recordings_dir}/`")
            self.program_md = gui.add_markdown("")
        self.rec_btn.on_click(lambda _e: app.start_recording())
        self.stop_btn.on_click(lambda _e: app.stop_recording(wait=False))

    def start(self, path: str | Path | None = None) -> Path:
        app = self.app
        if path is None:
            stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
            path = app.recordings_dir / f"{app.session.scene.name}-{stamp}.mcap"
            k = 1
            while Path(path).exists():
                path = app.recordings_dir / f"{app.session.scene.name}-{stamp}-{k}.mcap"
                k += 1
        out = app.session.start_recording(Path(path))
        if app.server is not None:
            self.rec_md.content = f"Recording to `{out}`"
            self.rec_btn.disabled = True
            self.stop_btn.disabled = False
        return out

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
        self.compile_thread = threading.Thread(target=self._compile, args=(path,), daemon=True)
        self.compile_thread.start()
        return path

    def _compile(self, path: Path) -> None:
        app = self.app
        try:
            prog = compile_recording(path)
            text = prog.listing()
            app.program_text = text
            md = f"Saved `{path}`\n\n**Program:**\n\n```\n{text}\n```"
        except Exception as e:  # shown to the user, not raised in a worker thread
            app.program_text = ""
            md = f"Saved `{path}`; compiling failed: {e}"
        if app.server is not None:
            self.rec_md.content = md
            self.program_md.content = md.split("\n\n", 1)[-1] if app.program_text else ""
