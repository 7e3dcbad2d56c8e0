"""``dlovr compile --sensor-noise N``: the compiled program's detections are set for that sensor."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from dlovr.cli import main
from dlovr.model.detection import for_sensor
from dlovr.model.program import Program

ROOT = Path(__file__).resolve().parents[2]


def test_compile_sets_detections_for_the_sensor_noise(tmp_path):
    r = CliRunner().invoke(main, ["compile", str(ROOT / "recordings/table.mcap"), "--sensor-noise", "0.02",
                                  "-o", str(tmp_path)])
    assert r.exit_code == 0, r.output
    prog = Program.load(tmp_path / "table.program.json")
    dets = [d for m in prog.classed for d in m.detection if d.cls != "S"]
    assert dets and all(d.params["sensor_noise_n"] == 0.02 for d in dets)
    for d in dets:
        assert for_sensor(d.cls, d.params, 0.02)[0] == d.params  # set once: running adds nothing
        assert all(d.derivation[k].startswith("derived: ") for k in ("sensor_noise_n",))
    assert "sensor_noise_n=0.02" in (tmp_path / "table.program.txt").read_text()


def test_a_plain_compile_after_one_for_a_sensor_is_not_skipped(tmp_path):
    """The compile cache keeps the sensor noise a program was set for: a plain compile into the same
    folder makes the plain program again instead of keeping the sensor's as "unchanged"."""
    rec = str(ROOT / "recordings/table.mcap")
    r = CliRunner().invoke(main, ["compile", rec, "--sensor-noise", "0.02", "-o", str(tmp_path)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["compile", rec, "-o", str(tmp_path)])
    assert r.exit_code == 0 and "skipped" not in r.output, r.output
    prog = Program.load(tmp_path / "table.program.json")
    assert all("sensor_noise_n" not in d.params for m in prog.classed for d in m.detection)
