"""Periodic multisine excitation for FRF measurement (Makarov, Grossard, Rodriguez-Ayerbe and Dumur 2012, eq. 21-22).

A multisine of period N_p samples at sampling time T_s (Makarov et al. 2012, eq. 21),

    u(t) = sum_{k=1..F} A_k cos(w_k t + phi_k),   w_k = 2 pi l_k / (N_p T_s),

excites exactly the DFT lines l_k of one period, so an integer number of periods has no leakage.
Kinds:

- ``"random"``: every line of the band excited, phases uniform on [0, 2 pi) (eq. 21);
- ``"odd"``: the odd lines 2 l + 1 of the band (eq. 22), one odd line out of every group of
  ``detection_group`` consecutive odd lines left out at random (Schoukens, Pintelon, Rolain and
  Dobrowiecki 2001): the even lines and those odd *detection lines* carry no input, so output there
  is even and odd nonlinear distortion (:func:`mocapfj.ident.frf.estimate_frf` reports both).

Amplitude shaping: `shape` gives the relative amplitude of each excited line (a callable of the
frequency in Hz, or an array), the whole signal scaled to the requested RMS. Crest factor
(peak / RMS) minimisation: from the random phases, iterative clipping (Van der Ouderaa, Schoukens
and Renneboog 1988): the period is clipped at a level below its peak, its excited lines keep the
clipped signal's phases and get their designed amplitudes back, unexcited lines are zeroed; the
best period met is kept. The result is still a multisine with exactly the designed amplitude
spectrum; the phases remain a seeded random draw (a different seed, a different realisation).
Schroeder (1970) phases are available as a deterministic alternative (``crest="schroeder"``).

A design plays in the simulator as a motor-position reference: :meth:`Multisine.to_reference` gives
the ``[joints.reference]`` table of a scenario file (the Fourier series of
:func:`mocapfj.synth.scenario.reference_trajectory` at f0 = 1 / (N_p T_s), zero amplitude on the
lines not excited), :func:`write_multisine_reference` writes it as TOML.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Multisine", "design_multisine", "multisine_realisations", "crest_factor", "schroeder_phases",
           "write_multisine_reference", "MULTISINE_KINDS"]

MULTISINE_KINDS = ("odd", "random")


@dataclass(frozen=True, eq=False)
class Multisine:
    """One period of a multisine and its line plan.

    Attributes
    ----------
    fs_hz : float
        Sampling rate 1 / T_s, Hz.
    n_samples : int
        Period length N_p (even), samples.
    lines : (F,) int
        Excited DFT lines l_k (frequency l_k fs / N_p).
    amplitudes : (F,) float
        A_k, in the unit of the signal (rad for a motor-position reference).
    phases : (F,) float
        phi_k of the cosines, rad.
    kind : str
        "odd" or "random".
    detection_odd, detection_even : (D,) int
        Unexcited odd and even lines inside the band [lines.min(), lines.max()].
    seed : int
        Seed of the random phases (and of the detection lines).
    """

    fs_hz: float
    n_samples: int
    lines: np.ndarray
    amplitudes: np.ndarray
    phases: np.ndarray
    kind: str
    detection_odd: np.ndarray
    detection_even: np.ndarray
    seed: int

    @property
    def f0_hz(self) -> float:
        """Frequency resolution fs / N_p, Hz (the period's inverse)."""
        return self.fs_hz / self.n_samples

    @property
    def period_s(self) -> float:
        return self.n_samples / self.fs_hz

    @property
    def f_hz(self) -> np.ndarray:
        """(F,) excited frequencies, Hz."""
        return self.lines * self.f0_hz

    def period(self) -> np.ndarray:
        """(N_p,) one period sampled at n T_s, n = 0..N_p-1 (an inverse real FFT)."""
        X = np.zeros(self.n_samples // 2 + 1, complex)
        X[self.lines] = 0.5 * self.n_samples * self.amplitudes * np.exp(1j * self.phases)
        return np.fft.irfft(X, self.n_samples)

    def signal(self, n_periods: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """t (n_periods N_p,) s and u (n_periods N_p,): the period repeated."""
        if int(n_periods) != n_periods or n_periods < 1:
            raise InputError(None, "n_periods", "a positive whole number of periods", n_periods)
        u = np.tile(self.period(), int(n_periods))
        return np.arange(u.size) / self.fs_hz, u

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray]:
        """u(t) and u'(t) at any times t (T,) s, from the sum of cosines (eq. 21)."""
        t = np.asarray(t, dtype=np.float64)
        w = 2 * np.pi * self.f_hz
        arg = t[..., None] * w + self.phases
        return (self.amplitudes * np.cos(arg)).sum(-1), -(self.amplitudes * w * np.sin(arg)).sum(-1)

    @property
    def crest_factor(self) -> float:
        return crest_factor(self.period())

    @property
    def rms(self) -> float:
        return float(np.sqrt(0.5 * np.sum(self.amplitudes ** 2)))

    def to_reference(self, q0_rad: float = 0.0, ramp_s: float | None = None) -> dict:
        """The ``[joints.reference]`` table of a scenario file playing this multisine as q_ref.

        q_ref(t) = q0 + s(t) sum_l a_l [sin(2 pi l f0 t + p_l) - sin p_l], f0 = fs / N_p, with
        a_l = A_k, p_l = phi_k + pi / 2 on the excited lines and 0 elsewhere: the multisine plus a
        constant, faded in over `ramp_s` (default one period; discard the first periods as transient).
        """
        n = int(self.lines.max())
        a, p = np.zeros(n), np.zeros(n)
        a[self.lines - 1] = self.amplitudes
        p[self.lines - 1] = np.mod(self.phases + np.pi / 2, 2 * np.pi)
        return {"f0_hz": float(self.f0_hz), "q0_rad": float(q0_rad), "amplitudes_rad": a.tolist(),
                "phases_rad": p.tolist(), "ramp_s": float(self.period_s if ramp_s is None else ramp_s)}

    def to_dict(self) -> dict:
        return {"fs_hz": self.fs_hz, "n_samples": self.n_samples, "kind": self.kind, "seed": self.seed,
                "f0_hz": self.f0_hz, "lines": self.lines.tolist(), "f_hz": self.f_hz.tolist(),
                "amplitudes": self.amplitudes.tolist(), "phases_rad": self.phases.tolist(),
                "detection_odd": self.detection_odd.tolist(), "detection_even": self.detection_even.tolist(),
                "rms": self.rms, "crest_factor": self.crest_factor}


def crest_factor(x) -> float:
    """Peak over RMS of a signal x (T,)."""
    x = np.asarray(x, dtype=np.float64)
    return float(np.max(np.abs(x)) / np.sqrt(np.mean(x * x)))


def schroeder_phases(amplitudes) -> np.ndarray:
    """Schroeder (1970) phases for consecutive lines of amplitudes A (F,):
    phi_k = -2 pi sum_{l<k} (k - l) p_l, p_l = A_l^2 / sum A^2 (a low crest factor for any spectrum)."""
    a = np.asarray(amplitudes, dtype=np.float64)
    p = a ** 2 / np.sum(a ** 2)
    k = np.arange(a.size)
    return np.mod(-2 * np.pi * np.array([np.sum((kk - k[:kk]) * p[:kk]) for kk in k]), 2 * np.pi)


def _clip_phases(n: int, lines, amps, phases, iterations: int) -> np.ndarray:
    """Iterative clipping (Van der Ouderaa, Schoukens and Renneboog 1988); returns the best phases."""
    X = np.zeros(n // 2 + 1, complex)
    mag = 0.5 * n * amps

    def synth(ph):
        X[:] = 0
        X[lines] = mag * np.exp(1j * ph)
        return np.fft.irfft(X, n)

    best, best_cf = phases, crest_factor(synth(phases))
    ph = phases
    for it in range(iterations):
        x = synth(ph)
        rms = np.sqrt(np.mean(x * x))
        level = rms * max(1.0, crest_factor(x) * (0.9 - 0.3 * it / max(iterations, 1)))
        ph = np.angle(np.fft.rfft(np.clip(x, -level, level))[lines])
        cf = crest_factor(synth(ph))
        if cf < best_cf:
            best, best_cf = ph, cf
    return np.mod(best, 2 * np.pi)


def design_multisine(fs_hz: float, n_samples: int, f_min_hz: float, f_max_hz: float, *, kind: str = "odd",
                     rms: float = 1.0, shape=None, detection_group: int = 3, crest: str = "clip",
                     crest_iterations: int = 200, seed: int = 0) -> Multisine:
    """A multisine over [f_min_hz, f_max_hz] (Makarov et al. 2012, eq. 21-22).

    Parameters
    ----------
    fs_hz : float
        Sampling rate, Hz.
    n_samples : int
        Period N_p, samples (even, >= 8).
    f_min_hz, f_max_hz : float
        Band; lines l with f_min <= l fs / N_p <= f_max (0 < f_min < f_max < fs / 2).
    kind : "odd" or "random"
        Odd lines with odd detection lines, or every line of the band.
    rms : float
        RMS of the signal (signal unit, e.g. rad).
    shape : callable f_hz (F,) -> (F,), array (F,) or None
        Relative amplitude of each excited line (positive); None: flat.
    detection_group : int
        kind "odd": one odd line out of every group of this many is left out (0: none).
    crest : "clip", "schroeder" or "none"
        Crest-factor minimisation: iterative clipping from the random phases, Schroeder phases, or
        the random phases as drawn.
    seed : int
        The random phases and detection lines (numpy default_rng).
    """
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    if int(n_samples) != n_samples or n_samples < 8 or n_samples % 2:
        raise InputError(None, "n_samples", "an even period length of at least 8 samples", n_samples)
    n_samples = int(n_samples)
    if kind not in MULTISINE_KINDS:
        raise InputError(None, "kind", f"one of {', '.join(MULTISINE_KINDS)}", kind)
    if crest not in ("clip", "schroeder", "none"):
        raise InputError(None, "crest", "clip, schroeder or none", crest)
    if not (np.isfinite(rms) and rms > 0):
        raise InputError(None, "rms", "a positive RMS", rms)
    f0 = fs_hz / n_samples
    if not (0 < f_min_hz < f_max_hz < fs_hz / 2):
        raise InputError(None, "f_min_hz, f_max_hz", f"0 < f_min < f_max < fs / 2 = {fs_hz / 2:.6g} Hz",
                         (f_min_hz, f_max_hz))
    lo, hi = max(1, int(np.ceil(f_min_hz / f0 - 1e-9))), min(n_samples // 2 - 1, int(np.floor(f_max_hz / f0 + 1e-9)))
    band = np.arange(lo, hi + 1)
    rng = np.random.default_rng(seed)
    if kind == "odd":
        odd = band[band % 2 == 1]
        det = np.empty(0, int)
        if detection_group and detection_group > 1:
            g = int(detection_group)
            groups = odd[: odd.size // g * g].reshape(-1, g)
            det = groups[np.arange(groups.shape[0]), rng.integers(0, g, groups.shape[0])] if groups.size else det
        lines = np.setdiff1d(odd, det)
    else:
        lines, det = band, np.empty(0, int)
    if lines.size < 2:
        raise InputError(None, "f_min_hz, f_max_hz", f"a band holding at least 2 excited lines (resolution "
                         f"{f0:.4g} Hz)", f"{lines.size} line(s)", hint="widen the band or lengthen the period")
    f = lines * f0
    if shape is None:
        rel = np.ones(lines.size)
    else:
        rel = np.asarray(shape(f) if callable(shape) else shape, dtype=np.float64).ravel()
        if rel.shape != lines.shape or not np.all(np.isfinite(rel)) or np.any(rel <= 0):
            raise InputError(None, "shape", f"{lines.size} positive finite relative amplitudes", rel.shape)
    amps = rel * rms / np.sqrt(0.5 * np.sum(rel ** 2))
    phases = rng.uniform(0.0, 2 * np.pi, lines.size)
    if crest == "schroeder":
        phases = schroeder_phases(amps)
    elif crest == "clip":
        phases = _clip_phases(n_samples, lines, amps, phases, int(crest_iterations))
    lo_l, hi_l = lines.min(), lines.max()
    inside = np.arange(lo_l, hi_l + 1)
    unexcited = np.setdiff1d(inside, lines)
    return Multisine(fs_hz=float(fs_hz), n_samples=n_samples, lines=lines, amplitudes=amps, phases=phases, kind=kind,
                     detection_odd=unexcited[unexcited % 2 == 1], detection_even=unexcited[unexcited % 2 == 0],
                     seed=int(seed))


def multisine_realisations(design: Multisine, n: int, *, crest: str = "clip", crest_iterations: int = 200,
                           seed: int = 1) -> list[Multisine]:
    """`n` realisations of `design`: the same lines and amplitudes, new random phases each
    (seeds seed, seed + 1, ...), crest factor minimised as in :func:`design_multisine`.
    Averaging an FRF over them averages out the stochastic nonlinear distortions (Schoukens et al. 2001)."""
    if int(n) != n or n < 1:
        raise InputError(None, "n", "a positive number of realisations", n)
    out = []
    for i in range(int(n)):
        rng = np.random.default_rng(seed + i)
        ph = rng.uniform(0.0, 2 * np.pi, design.lines.size)
        if crest == "clip":
            ph = _clip_phases(design.n_samples, design.lines, design.amplitudes, ph, int(crest_iterations))
        out.append(Multisine(design.fs_hz, design.n_samples, design.lines, design.amplitudes, ph, design.kind,
                             design.detection_odd, design.detection_even, seed + i))
    return out


def write_multisine_reference(path, design: Multisine, *, q0_rad: float = 0.0, ramp_s: float | None = None) -> None:
    """Write ``[joints.reference]`` (TOML) playing `design` as a motor-position reference
    (:meth:`Multisine.to_reference`); it replaces the reference table of a one-joint scenario file."""
    from ..io.tomlio import write_toml

    write_toml(path, {"joints": {"reference": design.to_reference(q0_rad, ramp_s)}})
