"""An interference line (mains pickup) in every record's residual is told from the model's misfit."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from physics.diagnose.interference import find_line
from physics.diagnose.verdict import Verdict

FS = 250.0
T = np.arange(int(60 * FS)) / FS


@dataclass
class _Rec:
    v_d: np.ndarray
    kind: str
    fs_d: float = FS


def _records(kinds=("broadband", "steps")):
    sweep = np.sin(2 * np.pi * (0.1 * T + 0.5 * (20 - 0.1) / 60 * T ** 2))
    square = np.sign(np.sin(2 * np.pi * 0.1 * T))
    tone = np.sin(2 * np.pi * 1.0 * T)
    drive = {"broadband": sweep, "steps": square, "tone": tone}
    return [_Rec(drive[k], k) for k in kinds]


def _case(records, hum, seed=0, f=50.0, amp=3e-6, driven=False):
    """(residuals, predictions): white noise of 1 µm, plus a sinusoid at ``f`` in the records ``hum``
    says; with ``driven`` the prediction holds it too (the drive makes it)."""
    rng = np.random.default_rng(seed)
    resid, pred = [], []
    for r, h in zip(records, hum):
        line = amp * np.sin(2 * np.pi * f * T + rng.uniform(0, 2 * np.pi)) if h else 0.0 * T
        resid.append(rng.normal(0, 1e-6, T.size) + line)
        pred.append(1e-4 * r.v_d + (line if driven else 0.0))
    return resid, pred


def test_a_line_in_every_record_that_the_drive_does_not_make_is_found_with_its_level():
    recs = _records()
    line = find_line(recs, *_case(recs, [True, True]))
    assert line is not None and line.freq_hz == pytest.approx(50.0, abs=0.1)
    assert line.rms == pytest.approx(3e-6 / np.sqrt(2), rel=0.1) and min(line.share) > 0.7
    text = line.text(np.hypot(1e-6, line.rms), 1e-6, 1.3)     # the model leaves the noise and the line
    assert "50 Hz" in text and "not the actuator's physics" in text and "within 1.3×" in text
    assert "1.00× the noise floor, within" in text and "still above" in line.text(6e-6, 1e-6, 1.3)
    v = Verdict("not explained by the catalog", [], {}, None, 3.2e-6, 1e-6, "test", remaining_kind="base mismatch",
                interference=text)
    remains = next(s for s in v.lines() if s.startswith("What remains:"))
    assert "a narrow line at 50 Hz" in remains and "mismatch of the model's own base forms" not in remains
    assert v.to_dict()["interference"] == text
    v.interference = ""
    assert "mismatch of the model's own base forms" in next(s for s in v.lines() if s.startswith("What remains:"))


@pytest.mark.parametrize("why", ["noise only", "one record", "driven", "identical drives", "a harmonic"])
def test_what_is_not_an_interference_line_is_not_reported(why):
    recs = _records({"identical drives": ("tone", "tone"), "a harmonic": ("tone", "steps")}.get(why, ("broadband", "steps")))
    hum = [why != "noise only", why != "one record"]
    f = 3.0 if why == "a harmonic" else 50.0           # the tone drive's third harmonic: a nonlinearity's
    assert find_line(recs, *_case(recs, hum, f=f, driven=why == "driven")) is None
    assert find_line(recs[:1], *_case(recs[:1], [True])) is None       # one record cannot tell
