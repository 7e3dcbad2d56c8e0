"""Compile a folder of recorded demonstrations (MCAP) into macro programs.

Run from the repository root::

    python examples/compile_recordings.py                  # the sample recordings in recordings/
    python examples/compile_recordings.py my_demos/ out/

Writes ``<name>.program.json`` and ``<name>.program.txt`` per recording into the output folder
(default: a temporary one, removed at the end) and prints each program's macros: index, transition
class, risk, and the principal situation it leads to.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from dlovr.outputs import write_output
from dlovr.recording import RecordingError, compile_recording, find_recordings

ROOT = Path(__file__).resolve().parent.parent


def main(folder: str, out_dir: str) -> None:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for path in find_recordings([folder]):
        try:
            program = compile_recording(path)  # reads only the recording's contact-state channel
        except RecordingError as e:  # a damaged file is named, the others still compile
            print(f"{path.name}: {e}")
            continue
        write_output(out / f"{path.stem}.program.json", program.dumps())  # atomic: never half a file
        write_output(out / f"{path.stem}.program.txt", program.listing())
        n = len(program.macros)
        print(f"{path.name}: {n} macro{'' if n == 1 else 's'} -> {out / path.stem}.program.json")
        for m in program.macros:
            print(f"  {m.index:2}  {m.label:4}  {m.to_situation}")


if __name__ == "__main__":
    src = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "recordings")
    if len(sys.argv) > 2:
        main(src, sys.argv[2])
    else:
        with tempfile.TemporaryDirectory(prefix="dlovr-programs-") as tmp:
            main(src, tmp)
