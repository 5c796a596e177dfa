"""One recording prepared for the many comparisons discovery makes on it.

Discovery refits candidate effects by output error and judges each on held-out evidence: dozens of
simulations of one recording, each compared in one band. :class:`Evidence` prepares what depends
on the recording alone (the recorded deflection and torque in the band, their SDs, the noise of
each channel from the nominal model's comparison) and scores a model with its simulation and the
two low-passes of its prediction only. :meth:`Evidence.fit` equals
``simulate_joint(model, ..., band_hz=band).fit`` (the comparison is linear in the prediction;
tests/discover/test_evidence.py), at a fraction of its cost.

:meth:`Evidence.residual` is the weighted in-band residual whose squared norm the fit is a
function of: fit = 100 (1 - ||residual||), the deflection's and the torque's residuals each
divided by sqrt(2 n) times the recorded signal's in-band SD (docs/conventions.md, "Fit and noise
floor"). Least squares on it maximises the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..dynamics import JointModel
from ..types import JointSignals
from .compare import in_band, fit_change_sd
from .model import OutputError, coupling_input, link_context, predict, simulate_signals

__all__ = ["Evidence", "Score"]


@dataclass(frozen=True, eq=False)
class Score:
    """A model scored on an :class:`Evidence`: its fit % (-inf when it cannot be simulated), and its
    predicted deflection and torque (T,) (None when it cannot)."""

    fit: float
    delta_sim: np.ndarray | None = None
    u_sim: np.ndarray | None = None


class Evidence:
    """A recording (one joint's signals, the other joints' accelerations for coupling terms)
    prepared for comparisons in one band (module docstring).

    s : JointSignals; others : {joint: (T,) rad/s^2}; band_hz : the comparison band; noise_from :
    the OutputError whose noise estimates (per channel, in band) the SDs of changes use (the
    nominal model's comparison on this recording, in this band), or None to make it from `model`;
    model : the model the noise comes from when `noise_from` is None.
    """

    def __init__(self, s: JointSignals, others: dict, band_hz: float, *, model: JointModel | None = None,
                 noise_from: OutputError | None = None, trim_s: float = 1.0, name: str = ""):
        self.s, self.others, self.band_hz, self.trim_s, self.name = s, dict(others), float(band_hz), trim_s, name
        t, q, q_m, u = (np.asarray(a, dtype=np.float64) for a in (s.t, s.q, s.q_m, s.u))
        self.t, self.q, self.q_m, self.u = t, q, q_m, u
        self.fs = 1.0 / float(np.median(np.diff(t)))
        self.inner = (t >= t[0] + trim_s) & (t <= t[-1] - trim_s)
        idx = np.flatnonzero(self.inner)
        self.sl = slice(int(idx[0]), int(idx[-1]) + 1)
        self._rec = {}
        if noise_from is None:
            if model is None:
                raise ValueError("Evidence needs noise_from or model")
            noise_from = simulate_signals(model, s, self.others, trim_s=trim_s, band_hz=self.band_hz)
        self.reference = noise_from
        self.noise_delta, self.noise_u = noise_from.noise_delta_rad, noise_from.noise_u_Nm

    def _recorded(self, sl: slice) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The recorded deflection and torque over `sl`, in band, and their SDs (kept per span)."""
        key = (sl.start, sl.stop)
        if key not in self._rec:
            d = (self.q_m - self.q)[sl]
            ok = np.isfinite(d)
            ar = np.arange(d.size)
            d = np.interp(ar, ar[ok], d[ok])
            yd = in_band(d, self.fs, self.band_hz)
            yu = in_band(self.u[sl], self.fs, self.band_hz)
            self._rec[key] = (yd, yu, float(np.std(yd)), float(np.std(yu)))
        return self._rec[key]

    def _span(self, d_sim: np.ndarray) -> slice | None:
        keep = self.inner & np.isfinite(d_sim)
        if not keep.any():
            return None
        idx = np.flatnonzero(keep)
        return slice(int(idx[0]), int(idx[-1]) + 1)

    def _residuals(self, d_sim: np.ndarray, u_sim: np.ndarray, sl: slice | None = None):
        """(in-band deflection residual centred, in-band torque residual, sd_d, sd_u) over `sl`
        (default: the inner samples the simulation covers), or None."""
        sl = self._span(d_sim) if sl is None else sl
        if sl is None:
            return None
        yd, yu, sd_d, sd_u = self._recorded(sl)
        dh, uh = d_sim[sl], u_sim[sl]
        if not (np.isfinite(dh).all() and np.isfinite(uh).all()):
            ar = np.arange(dh.size)
            okd, oku = np.isfinite(dh), np.isfinite(uh)
            if not (okd.any() and oku.any()):
                return None
            dh, uh = np.interp(ar, ar[okd], dh[okd]), np.interp(ar, ar[oku], uh[oku])
        rd = yd - in_band(dh, self.fs, self.band_hz)
        rd = rd - rd.mean()
        ru = yu - in_band(uh, self.fs, self.band_hz)
        return rd, ru, sd_d, sd_u

    def predict(self, model: JointModel) -> tuple[np.ndarray, np.ndarray] | None:
        """(deflection, torque) (T,) the model predicts on this recording, or None when it cannot be
        simulated (an element that overflows, a stiff model past its budget)."""
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                q_sim, u_sim = predict(model, self.t, self.q, self.q_m, coupling_input(model, self.others),
                                       context=link_context(model, self.others))
        except (RuntimeError, FloatingPointError, ValueError, ArithmeticError, np.linalg.LinAlgError):
            return None
        return self.q_m - q_sim, u_sim

    def score(self, model: JointModel) -> Score:
        """The model's fit % on this recording in the band (module docstring)."""
        p = self.predict(model)
        if p is None:
            return Score(-math.inf)
        r = self._residuals(*p)
        if r is None:
            return Score(-math.inf, *p)
        rd, ru, sd_d, sd_u = r
        if not (sd_d > 0 and sd_u > 0):
            return Score(math.nan, *p)
        e_d = math.sqrt(float(np.mean(rd ** 2))) / sd_d
        e_u = math.sqrt(float(np.mean(ru ** 2))) / sd_u
        f = 100.0 * (1.0 - math.sqrt((e_d ** 2 + e_u ** 2) / 2.0))
        return Score(f if math.isfinite(f) else -math.inf, *p)

    def fit(self, model: JointModel) -> float:
        return self.score(model).fit

    def residual(self, model: JointModel, size: int | None = None) -> np.ndarray:
        """The weighted in-band residual (module docstring), 1-D; a large constant vector of length
        `size` when the model cannot be simulated (least squares then steps back)."""
        p = self.predict(model)
        r = None if p is None else self._residuals(*p)
        if r is None or not all(np.isfinite(x).all() for x in r[:2]):
            return np.full(size or 2, 1e3)
        rd, ru, sd_d, sd_u = r
        n = rd.size
        return np.concatenate([rd / (sd_d * math.sqrt(2 * n)), ru / (sd_u * math.sqrt(2 * n))])

    def change_sd(self, a: Score, b: Score, with_size: bool = False) -> float | tuple[float, float]:
        """The SD (points) of b.fit - a.fit that this recording's noise alone gives, and with
        `with_size` the change's size (:func:`.compare.fit_change_sd`)."""
        nan = (math.nan, math.nan) if with_size else math.nan
        if a.delta_sim is None or b.delta_sim is None or not math.isfinite(a.fit):
            return nan
        keep = self.inner & np.isfinite(a.delta_sim) & np.isfinite(b.delta_sim)
        sl = self._span(np.where(keep, 0.0, np.nan))
        if sl is None:
            return nan
        _, _, sd_d, sd_u = self._recorded(sl)
        return fit_change_sd(self.t, keep, self.band_hz, a.fit,
                             [(sd_d, self.noise_delta, b.delta_sim - a.delta_sim, True),
                              (sd_u, self.noise_u, b.u_sim - a.u_sim)], with_size=with_size)

    def compare(self, model: JointModel) -> OutputError:
        """The full comparison (:func:`.model.simulate_joint`) in this band."""
        return simulate_signals(model, self.s, self.others, trim_s=self.trim_s, band_hz=self.band_hz)
