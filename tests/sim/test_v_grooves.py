"""A cable in V grooves built in the test, recorded with ``dlovr record``: the gripped end's contact
(docs/model.md, section 2) in a 120° groove."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from v_groove_scenes import v_groove

from dlovr import plausibility
from dlovr.cli import main
from dlovr.recording import Recording, kept_states


def record(script: Path, out: Path) -> Path:
    r = CliRunner().invoke(main, ["record", "--script", str(script), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="module")
def held_across_120(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("v120")
    return record(v_groove(tmp, 120.0, 1e8, -0.045, 0.001, 0.3), tmp / "v120.mcap")


def test_the_gripped_ends_contact_is_a_contact_of_the_first_segment(held_across_120):
    """A cable held across a 120° V groove, its held end pressed into the near flank: V_S is V/G, and
    what it touches is an E contact at E_1 that carries the largest force (issue 27, item 4); the far
    flank's edge where the cable rests is a contact of its own."""
    rec = Recording(held_across_120)
    last = kept_states(rec)[-1]
    first = last.situation.contacts[1]
    assert last.situation.contacts[0].state.name == "V/G"
    assert first.state.name == "E/F" and first.span == (1, 1), last.situation.format()
    assert len(last.situation.successional()) == 2, last.situation.format()  # and the far flank
    payload = rec.states()[-1]
    forces = [c["force"] for c in payload["contacts"]]
    assert payload["contacts"][1]["state"] == "E/F" and forces[1] == max(forces) > 1.0, payload
    assert payload["topological"].startswith("VS/G & E1/v.F")


PUSHED_60_BOUND = 0.0012
"""The deepest a stiff cable pushed 40 mm along a 60° V may sink (m): 0.95 mm with the contacts'
impedance ``CONTACT_SOLIMP`` rising to 0.999 (docs/recordings.md, "Reducing jams"); 6.2 mm and a
divergence while it rose to 0.99 only."""


@pytest.fixture(scope="module")
def pushed_into_60(tmp_path_factory) -> tuple[Path, str]:
    """A stiff cable (E = 1 GPa) along a 60° V, its held end pushed 40 mm into it: a wedge that made
    MuJoCo's soft contacts give way (the cable sank 6.2 mm and the run diverged while the contacts'
    impedance rose to 0.99 only). Recorded with the penetration bound lowered to 0.06 of the radius
    (0.3 mm), so that the push's penetration is a warning episode whose peak is the deepest the cable
    sank."""
    tmp = tmp_path_factory.mktemp("v60")
    out = tmp / "v60.mcap"
    script = v_groove(tmp, 60.0, 1e9, -0.06, 0.040, 0.3, pose="along")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plausibility, "PENETRATION_BOUND", 0.06)
        r = CliRunner().invoke(main, ["record", "--script", str(script), "-o", str(out)])
    assert r.exit_code == 0, r.output  # no divergence
    return out, r.output


def test_a_cable_pushed_into_a_narrow_v_sinks_about_a_millimetre_only(pushed_into_60):
    """The jam reduced with MuJoCo's contact settings (issue 27, item 5): the 40 mm push into the
    60° V sinks less than :data:`PUSHED_60_BOUND`, far within the plausibility bound (2.5 mm)."""
    out, _ = pushed_into_60
    eps = Recording(out).warnings()
    assert eps and {ep.kind for ep in eps} == {"penetration"}
    assert max(ep.peak for ep in eps) < PUSHED_60_BOUND < plausibility.PENETRATION_BOUND * 0.005


def test_a_penetration_beyond_its_bound_is_reported_as_implausible(pushed_into_60):
    """docs/recordings.md, plausibility warnings (issue 27, item 5): a stretch of steps beyond the
    penetration bound is one warning event in the recording, said by `record` and by `dlovr states`
    (on stderr: the table on stdout stays as it is). The bound is lowered here (see the fixture): no
    built-in case sinks beyond the real one any more."""
    out, said = pushed_into_60
    eps = Recording(out).warnings()
    ep = max(eps, key=lambda e: e.peak)
    assert ep.kind == "penetration" and ep.where == "v"
    assert ep.peak > ep.bound == pytest.approx(0.0003) and ep.end >= ep.start > 0.3
    assert f"warning: implausible simulation: {ep.text()}" in said
    r = CliRunner().invoke(main, ["states", str(out)])
    assert r.exit_code == 0 and "warning: implausible simulation: penetration" in r.output
    r = CliRunner().invoke(main, ["states", str(out), "--format", "json"])
    assert r.exit_code == 0


def test_the_plausible_recordings_have_no_warnings(held_across_120):
    assert Recording(held_across_120).warnings() == []
