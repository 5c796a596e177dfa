"""An effect's SDs carry the spread between forms the recordings do not tell apart
(mocapfj.discover.tournament.form_sds, engine._sds_out)."""

from __future__ import annotations

from mocapfj.discover.engine import _sds_out
from mocapfj.discover.tournament import form_sds


def test_a_form_the_recordings_do_not_decide_widens_the_sds_by_its_spread():
    """Either form as likely: the chosen value is off by the spread d half the time, so its SD is
    the mixture's RMS about it, sqrt(SD^2 + d^2 / 2): 0.5 and d = 2 give sqrt(0.25 + 2) = 1.5. A
    parameter without a spread keeps its SD, and a list-valued one is left as it is."""
    out = form_sds({"fs": 0.5, "vs": 0.01, "a": [1.0, 2.0]}, {"fs": -2.0, "a": 3.0})
    assert out["fs"] == 1.5 and out["vs"] == 0.01 and out["a"] == [1.0, 2.0]


def test_the_reported_sds_are_widened_and_say_by_what():
    """The effect's output: its fit's SDs widened by the spread of the parameters that have one,
    and that spread reported beside them (`sds_include_form_spread`); without a spread, as fitted."""
    out = _sds_out({"parameter_sds": {"fs": 0.5, "vs": 0.01}, "form_spread": {"fs": -2.0, "fc": 1.0}})
    assert out == {"parameter_sds": {"fs": 1.5, "vs": 0.01}, "sds_include_form_spread": {"fs": -2.0}}
    assert _sds_out({"parameter_sds": {"fs": 0.5}}) == {"parameter_sds": {"fs": 0.5}}
    assert _sds_out({}) == {}
