"""The two-inertia flexible joint fitted to a measured FRF, its modes and their uncertainty.

Model (Makarov, Grossard, Rodriguez-Ayerbe and Dumur 2012, eq. 5-7, one joint, gravity linearised away;
Lightcap and Banks (2007), eq. 4 with the spring damping d):

    J q_m'' + b q_m' + k (q_m - q) + d (q_m' - q') = u          (motor, torque u on the link side)
    I q''   + v q'   = k (q_m - q) + d (q_m' - q')               (link)

gives, with Z(s) = d s + k and D(s) = J I s^3 + (J (v + d) + (b + d) I) s^2 + (J k + I k + b (v + d) + d v) s
+ k (b + v),

    q_m / u = (I s^2 + (v + d) s + k) / (s D(s))     (``output="motor"``: colocated, anti-resonance then resonance)
    q   / u = (d s + k) / (s D(s))                    (``output="link"``: the resonance only)

The anti-resonance is the link swinging on the spring with the motor held, omega_a^2 = k / I; the
resonance the two inertias against each other, omega_r^2 ~ k (1/I + 1/J).

Gravity, when the rigid part is known (Makarov et al.'s physically parametrised model): a link
under gravity G(q) (I q'' + v q' + G(q) = spring torque) oscillates about its operating point q0
with the extra stiffness g = G'(q0), known from the rigid model (for a single joint G(q) =
-mglx sin q + mgly cos q, so g = -mglx cos q0 - mgly sin q0; negative when gravity pulls the link
away from q0). The link equation gains g q, the anti-resonance becomes omega_a^2 = (k + g) / I and the
denominator s D(s) becomes the quartic

    J I s^4 + (J (v + d) + (b + d) I) s^3 + (J (k + g) + I k + b (v + d) + d v) s^2 + (k (b + v) + g (b + d)) s + k g

(q_m / u has numerator I s^2 + (v + d) s + k + g). The linear fit without it reads g into k and I:
on PA-10 joint 2 at q0 = 0.3 rad (g = -104 N m/rad, 0.9 % of k) k came out +0.84 % and I +1.8 %
(benchmarks/bench_frf_crosscheck.py). g is given, never fitted: fitted it trades off against k.

Fit: weighted nonlinear least squares on the complex FRF (the maximum-likelihood criterion of a
FRF with circular complex Gaussian errors, Pintelon and Schoukens 2012, §7): minimise
sum_k |G_hat_k - G(j w_k, theta)|^2 / var_k with var_k the FRF's noise variance plus, where the detection lines
show a distortion above the noise, the stochastic nonlinear distortion's (``FRF.var_fit``), theta = (ln J,
ln I, ln k, d, b, v), d, b, v >= 0. The distortion is periodic, so the period-to-period spread misses it;
weighed by the noise alone, PA-10 joint 2 with its Coulomb friction (a 0.01 rad multisine, one
realisation) gave k within 3.7 % (RMS 2.1 % over 12 multisines), weighed by both within 1.4 % (RMS 0.8 %)
(benchmarks/bench_frf.py §6). The variances are the FRF's own, from the period-to-period spread, line by line (not
smoothed over frequency: a smoothed variance flattens the peak at the resonance, exactly where the
modes are decided, and the SDs of f_r came out 2.7x too small on the grid of benchmarks/bench_frf.py).
Their nu = M (P - 1) complex degrees of freedom per line inflate the chi-square by about
nu / (nu - 1), and few of them make the weights noisy. Covariance: (A^T A)^{-1} at the optimum (A
the Jacobian of the weighted residuals), times the reduced chi-square when that exceeds 1 (model
error or nonlinear distortion beyond the noise), times 1 + 3 / nu^2: an empirical allowance for
the noisy weights, measured in benchmarks/bench_frf.py §3 (without it the z RMS of k is 1.97 at
nu = 1 and 1.78 at nu = 2; at nu >= 6 it is 0.7-1.2 and the factor below 1.09). Modes: the anti-resonance from the numerator's complex roots, the resonance from D's,
f = |p| / 2 pi and zeta = -Re p / |p|; their SDs by the delta method.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from .frf import FRF
from .result import Parameter

__all__ = ["TWO_INERTIA_PARAMS", "FRF_MODELS", "Mode", "FRFFit", "two_inertia_frf", "two_inertia_modes",
           "fit_two_inertia"]

TWO_INERTIA_PARAMS = ("J", "I", "k", "d", "b", "v")
_NAMES = TWO_INERTIA_PARAMS + ("g",)
FRF_MODELS = ("two_inertia",)
_OUTPUTS = ("motor", "link")


@dataclass(frozen=True)
class Mode:
    """A resonance (pole pair) or anti-resonance (zero pair): frequency, damping ratio and SDs."""

    kind: str
    f_hz: float
    zeta: float
    f_hz_std: float
    zeta_std: float

    def to_dict(self) -> dict:
        return {"kind": self.kind, "f_hz": self.f_hz, "zeta": self.zeta, "f_hz_std": self.f_hz_std,
                "zeta_std": self.zeta_std}


@dataclass(frozen=True, eq=False)
class FRFFit:
    """The two-inertia model fitted to an FRF.

    params : dict name -> Parameter (J, I kg m^2; k N m/rad; d, b, v N m s/rad; g N m/rad), value and SD
    cov : (7, 7) covariance of (J, I, k, d, b, v, g) (rows and columns of held parameters zero, but
        for g held with an SD)
    modes : tuple of Mode, anti-resonance first (motor output), then the resonance
    chi2, dof : weighted residual sum of squares and its degrees of freedom (2 K - free parameters)
    G_fit : (K,) complex, the model at the FRF's frequencies
    output : "motor" or "link"
    gravity_stiffness, gravity_stiffness_std : the link's gravity stiffness and its SD, N m/rad:
        fitted (gravity_fitted), or held (its SD then counted in the other parameters' SDs)
    """

    params: dict
    cov: np.ndarray
    modes: tuple
    chi2: float
    dof: int
    G_fit: np.ndarray
    output: str
    model: str = "two_inertia"
    gravity_stiffness: float = 0.0
    gravity_stiffness_std: float = 0.0
    gravity_fitted: bool = False

    @property
    def chi2_red(self) -> float:
        return self.chi2 / max(self.dof, 1)

    def value(self, name: str) -> float:
        return self.params[name].value

    def to_dict(self) -> dict:
        return {"name": self.model, "output": self.output, "gravity_stiffness": self.gravity_stiffness,
                "gravity_stiffness_std": self.gravity_stiffness_std, "gravity_fitted": self.gravity_fitted,
                "params": {n: {"value": p.value, "std": p.std, "rel_std_pct": p.rel_std_pct,
                               **({} if p.determined else {"determined": False, "reason": p.reason})}
                           for n, p in self.params.items()},
                "chi2": self.chi2, "dof": self.dof, "chi2_red": self.chi2_red,
                "modes": [m.to_dict() for m in self.modes]}


def _polys(J, I, k, d, b, v, g=0.0):
    """Numerator coefficients (motor, link) and the denominator (highest power first): D(s), whose
    s factor the callers add, without gravity; the whole quartic with it (g != 0)."""
    if g == 0.0:
        D = np.array([J * I, J * (v + d) + (b + d) * I, J * k + I * k + b * (v + d) + d * v, k * (b + v)])
        return np.array([I, v + d, k]), np.array([d, k]), D
    D = np.array([J * I, J * (v + d) + (b + d) * I, J * (k + g) + I * k + b * (v + d) + d * v,
                  k * (b + v) + g * (b + d), k * g])
    return np.array([I, v + d, k + g]), np.array([d, k]), D


def two_inertia_frf(f_hz, J, I, k, d=0.0, b=0.0, v=0.0, *, output: str = "motor", g: float = 0.0) -> np.ndarray:
    """G(j 2 pi f) of the two-inertia joint, (K,) complex, rad / (N m), for f_hz (K,) > 0; g N m/rad
    the link's known gravity stiffness at the operating point (module docstring)."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=np.float64)
    nm, nl, D = _polys(J, I, k, d, b, v, g)
    den = s * np.polyval(D, s) if g == 0.0 else np.polyval(D, s)
    return np.polyval(nm if output == "motor" else nl, s) / den


def two_inertia_modes(J, I, k, d=0.0, b=0.0, v=0.0, *, output: str = "motor",
                      g: float = 0.0) -> list[tuple[str, float, float]]:
    """[(kind, f_hz, zeta)]: the anti-resonance (motor output, when its zeros are complex) and the resonance."""
    nm, _, D = _polys(J, I, k, d, b, v, g)
    out = []
    if output == "motor":
        out += [("antiresonance", *_fz(r)) for r in np.roots(nm) if r.imag > 0]
    # the resonance: the fastest complex pole pair (with gravity a second, slow pair can appear: the
    # whole joint swinging on gravity's stiffness, g > 0, which is not a mode of the drive)
    poles = [r for r in np.roots(D) if r.imag > 0]
    if poles:
        out.append(("resonance", *_fz(max(poles, key=abs))))
    return out


def _fz(p):
    return float(abs(p) / (2 * np.pi)), float(-p.real / abs(p))


def _initial(frf: FRF, output: str, g: float | None = 0.0):
    """Starting points (J, I, k, d, b, v, g) from the FRF's shape: rigid-body inertia M, viscosity
    B and (g None: fitted) the gravity stiffness c from the lowest lines, the mode frequencies from
    the dip and the peak of |G (M s^2 + B s + c)| (flat for a rigid body), then M, B, c again below
    the first mode. A held g is subtracted (c = g)."""
    f, G = frf.f_hz, frf.G
    w = 2 * np.pi * f

    def rigid(low):
        """M, B, c of 1/G = M s^2 + B s + c on the lines `low` (linear least squares; c = g when held)."""
        Z = 1.0 / G[low] - (0.0 if g is None else g)
        cols = [-w[low] ** 2, 1j * w[low]] + ([np.ones(int(low.sum()))] if g is None else [])
        A = np.column_stack(cols).astype(complex)
        mb = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.concatenate([Z.real, Z.imag]), rcond=None)[0]
        M = abs(mb[0]) if mb[0] != 0 else 1.0 / (np.abs(G[low][0]) * w[low][0] ** 2)
        return M, max(mb[1], 1e-6 * M * w[0]), (float(mb[2]) if g is None else g)

    M, B, c = rigid(np.arange(f.size) < min(3, f.size))
    a = np.abs(G * (-M * w ** 2 + 1j * B * w + c))   # ~1 below the modes: the rigid body divided out
    ia = int(np.argmin(a)) if output == "motor" else 0
    ir = ia + int(np.argmax(a[ia:]))
    if output == "motor" and (ia in (0, f.size - 1) or ir == ia):
        raise InputError(None, "frf", "an anti-resonance and a resonance inside the excited band (motor side)",
                         f"|G| (M s^2 + B s) without a dip then a peak over {f[0]:.3g}-{f[-1]:.3g} Hz",
                         hint="widen the multisine band around the joint's modes")
    f_first = f[ia] if output == "motor" else f[ir]
    low = f < 0.6 * f_first
    if low.sum() >= 2:
        M, B, c = rigid(low)
    starts = []
    if output == "motor":
        wa, wr = w[ia], w[ir]
        rho = max((wr / wa) ** 2 - 1, 1e-2)
        J = M / (1 + rho)
        I = M - J
        k = I * wa ** 2
        k = I * wa ** 2 - c                        # omega_a^2 = (k + g) / I
        if not k > 0:
            k = I * wa ** 2
        for z in (0.005, 0.03, 0.1):
            starts.append((J, I, k, 2 * z * wa * I, B / 2, B / 2, c))
    else:
        wr = w[ir]
        for rho in (0.3, 1.0, 3.0):
            J = M / (1 + rho)
            I = M - J
            k = wr ** 2 / (1 / I + 1 / J)
            starts.append((J, I, k, 0.03 * 2 * np.sqrt(k * I * J / (I + J)), B / 2, B / 2, c))
    return starts


def fit_two_inertia(frf: FRF, *, output: str = "motor", fixed: dict | None = None, f_band_hz=None,
                    gravity_stiffness: float | None = None, gravity_stiffness_std: float = 0.0) -> FRFFit:
    """Fit (J, I, k, d, b, v) of the two-inertia joint to `frf` by weighted nonlinear least squares.

    Parameters
    ----------
    frf : FRF
        From :func:`mocapfj.ident.frf.estimate_frf`; input torque (N m), output angle (rad).
    output : "motor" or "link"
        Which angle the FRF's output is. The link-side FRF determines 5 coefficients for 6
        parameters: hold one (`fixed`).
    fixed : dict name -> value or None
        Parameters held at known values (e.g. the rigid part known: ``{"J": ...}``).
    f_band_hz : (lo, hi) or None
        Fit only the lines inside this band.
    gravity_stiffness : float or None
        g = G'(q0), N m/rad, the link's gravity stiffness at the operating point (module
        docstring), held at this value (from the rigid model; 0 for a joint gravity does not act
        on). None: fitted with the rest (``params["g"]``) from the motor-side FRF, whose lowest
        lines carry it (|G| ~ 1 / ((J + I) w^2 - g) below the anti-resonance); held at 0 for a
        link-side FRF, which has one coefficient fewer.
    gravity_stiffness_std : float
        Its SD: the fit is repeated at g +- SD and half the change of every parameter and mode is
        added (in quadrature) to its SD (k takes up nearly all of it: dk/dg is about -1).
    """
    if not isinstance(frf, FRF):
        raise InputError(None, "frf", "an FRF (mocapfj.ident.frf.estimate_frf)", type(frf).__name__)
    if output not in _OUTPUTS:
        raise InputError(None, "output", "motor or link", output)
    fixed = dict(fixed or {})
    fit_g = gravity_stiffness is None and output == "motor"
    g = 0.0 if gravity_stiffness is None else float(gravity_stiffness)
    g_sd = float(gravity_stiffness_std)
    if not np.isfinite(g):
        raise InputError(None, "gravity_stiffness", "a finite gravity stiffness in N m/rad", gravity_stiffness)
    if not (np.isfinite(g_sd) and g_sd >= 0):
        raise InputError(None, "gravity_stiffness_std", "a finite SD >= 0 in N m/rad", gravity_stiffness_std)
    if g_sd > 0 and not fit_g:
        fit = fit_two_inertia(frf, output=output, fixed=fixed, f_band_hz=f_band_hz, gravity_stiffness=g)
        hi, lo = (fit_two_inertia(frf, output=output, fixed=fixed, f_band_hz=f_band_hz, gravity_stiffness=g + s * g_sd)
                  for s in (1.0, -1.0))
        dv = np.array([(hi.value(n_) - lo.value(n_)) / 2.0 for n_ in TWO_INERTIA_PARAMS] + [g_sd])
        cov = fit.cov + np.outer(dv, dv)
        params = {n_: Parameter(n_, fit.value(n_), float(np.sqrt(max(cov[i, i], 0.0))))
                  for i, n_ in enumerate(_NAMES)}
        modes = fit.modes
        if [m.kind for m in hi.modes] == [m.kind for m in fit.modes] == [m.kind for m in lo.modes]:
            modes = tuple(Mode(m.kind, m.f_hz, m.zeta, float(np.hypot(m.f_hz_std, (h.f_hz - l.f_hz) / 2.0)),
                               float(np.hypot(m.zeta_std, (h.zeta - l.zeta) / 2.0)))
                          for m, h, l in zip(fit.modes, hi.modes, lo.modes))
        return FRFFit(params=params, cov=cov, modes=modes, chi2=fit.chi2, dof=fit.dof, G_fit=fit.G_fit,
                      output=fit.output, gravity_stiffness=g, gravity_stiffness_std=g_sd)
    for n_, v_ in fixed.items():
        if n_ not in TWO_INERTIA_PARAMS or not np.isfinite(v_) or v_ < 0 or (n_ in "JIk" and v_ <= 0):
            raise InputError(None, f"fixed.{n_}", f"one of {TWO_INERTIA_PARAMS} with a valid value", v_)
    sel = np.ones(frf.f_hz.size, bool)
    if f_band_hz is not None:
        sel = (frf.f_hz >= f_band_hz[0]) & (frf.f_hz <= f_band_hz[1])
    if output == "link" and not fixed:
        raise InputError(None, "fixed", "one parameter held at a known value for a link-side FRF (e.g. the motor "
                         "inertia J): q / u has 5 independent coefficients for 6 parameters", "none")
    fixed = {**fixed, **({} if fit_g else {"g": g})}
    free = [i for i, n_ in enumerate(_NAMES) if n_ not in fixed]
    if 2 * sel.sum() <= len(free):
        raise InputError(None, "frf", f"more than {len(free) / 2:.0f} excited lines to fit {len(free)} parameters",
                         int(sel.sum()))
    f, G = frf.f_hz[sel], frf.G[sel]
    var = frf.var_fit[sel]
    sd = np.sqrt(np.maximum(var, (1e-10 * np.abs(frf.G[sel])) ** 2 + 1e-300) / 2.0)   # noise-free: 1e-10
    sub = FRF(f, G, var, None, frf.coherence[sel], frf.lines[sel], frf.estimator, frf.n_periods,
              frf.n_realisations, frf.fs_hz, frf.n_samples, frf.closed_loop, frf.distortion)
    shape_error = None
    try:
        starts = _initial(sub, output, None if fit_g else g)
    except InputError as e:
        if not fit_g:
            raise
        starts, shape_error = [], e       # the fit without g may still give a start (below)
    log = np.array([True, True, True, False, False, False, False])

    def full(x):
        th = np.empty(7)
        th[free] = x
        for i, n_ in enumerate(_NAMES):
            if n_ in fixed:
                th[i] = np.log(fixed[n_]) if log[i] else fixed[n_]
        return th

    def natural(th):
        return np.where(log, np.exp(np.clip(th, -700, 700)), th)

    def resid(x):
        with np.errstate(all="ignore"):              # a trial step far out: a large residual, not a warning
            p_ = natural(full(x))
            e = (G - two_inertia_frf(f, *p_[:6], output=output, g=p_[6])) / sd
            r = np.concatenate([e.real, e.imag])
        return np.where(np.isfinite(r), r, 1e150)

    lb = np.where(log, -np.inf, 0.0)
    lb[6] = -np.inf
    lb = lb[free]
    best = None

    def solve(p0):
        th0 = np.where(log, np.log(np.maximum(p0, 1e-300)), p0)
        x0 = np.clip(th0[free], lb, np.inf)
        x0 = np.where(np.isfinite(lb) & (x0 <= lb), lb + 1e-9, x0)
        try:
            return least_squares(resid, x0, bounds=(lb, np.inf), x_scale="jac", method="trf", max_nfev=2000,
                                 xtol=1e-12, ftol=1e-12)
        except ValueError:
            return None

    if fit_g:
        # also from the fit with g held at 0 (when that model fits at all: a strong gravity hides
        # its dip and peak), g free from there and from +-2 % of its k
        try:
            held = fit_two_inertia(frf, output=output, fixed={n_: v_ for n_, v_ in fixed.items() if n_ != "g"},
                                   f_band_hz=f_band_hz, gravity_stiffness=0.0)
            v0 = [held.value(n_) for n_ in TWO_INERTIA_PARAMS]
            starts = [tuple(v0) + (s * v0[2],) for s in (0.0, -0.02, 0.02)] + starts
        except InputError:
            if shape_error is not None:
                raise shape_error from None
    for p0 in starts:
        sol = solve(np.asarray(p0, dtype=np.float64))
        if sol is not None and (best is None or sol.cost < best.cost):
            best = sol
    if best is None or not np.all(np.isfinite(best.x)):
        raise InputError(None, "frf", "an FRF the two-inertia model can be fitted to", "no convergence")
    A = best.jac
    dof = 2 * f.size - len(free)
    chi2 = float(2 * best.cost)
    try:
        nu = frf.n_realisations * max(frf.n_periods - 1, 1)
        cov_x = np.linalg.inv(A.T @ A) * max(1.0, chi2 / max(dof, 1)) * (1.0 + 3.0 / nu ** 2)
    except np.linalg.LinAlgError:
        cov_x = np.full((len(free), len(free)), np.nan)
    th = full(best.x)
    val = natural(th)
    Jn = np.diag(np.where(log, val, 1.0))[:, free]          # d natural / d x
    cov = Jn @ cov_x @ Jn.T
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    D_fit = _polys(*val[:6], val[6])[2]
    if not (np.all(np.isfinite(val)) and np.all(np.isfinite(D_fit)) and D_fit[0] > 0
            and np.all(np.isfinite(D_fit[1:] / D_fit[0])) and min(val[0], val[1]) > 1e-9 * (val[0] + val[1])):
        raise InputError(None, "frf", "an FRF the two-inertia model can be fitted to",
                         "a fit that left the finite numbers or drove an inertia to zero",
                         hint="check the band covers both modes")
    # a singular curvature (NaN SDs): the fit does not determine its parameters; said, not hidden
    params = {n_: Parameter(n_, float(val[i]), float(std[i]), determined=bool(np.isfinite(std[i])),
                            reason=None if np.isfinite(std[i]) else
                            "the fit's curvature is singular: the FRF does not determine it")
              for i, n_ in enumerate(_NAMES)}
    g = float(val[6])
    if not val[2] + g > 0:
        raise InputError(None, "gravity_stiffness", f"a gravity stiffness the fitted spring outweighs (k + g > 0, "
                         f"k {val[2]:.4g} N m/rad)", g, hint="check its sign: g = G'(q0) with I q'' + G(q) = spring torque")
    base = two_inertia_modes(*val[:6], output=output, g=g)
    modes = []
    if base:
        def mode_vec(x):
            p_ = natural(full(x))
            m = two_inertia_modes(*p_[:6], output=output, g=p_[6])
            if [kk for kk, _, _ in m] != [kk for kk, _, _ in base]:
                return np.full(2 * len(base), np.nan)
            return np.array([v_ for _, ff, zz in m for v_ in (ff, zz)])

        m0 = mode_vec(best.x)
        D = np.empty((m0.size, best.x.size))
        for j in range(best.x.size):
            h = 1e-6 * max(abs(best.x[j]), 1e-3 if log[free[j]] else abs(best.x[j]) + 1e-8)
            xp, xm = best.x.copy(), best.x.copy()
            xp[j] += h
            xm[j] -= h
            if not log[free[j]] and xm[j] < 0:
                xm[j] = best.x[j]
                D[:, j] = (mode_vec(xp) - m0) / h
            else:
                D[:, j] = (mode_vec(xp) - mode_vec(xm)) / (xp[j] - xm[j])
        cm = D @ cov_x @ D.T
        sm = np.sqrt(np.maximum(np.diag(cm), 0.0))
        for i, (kind, fr, z) in enumerate(base):
            modes.append(Mode(kind, fr, z, float(sm[2 * i]), float(sm[2 * i + 1])))
    return FRFFit(params=params, cov=cov, modes=tuple(modes), chi2=chi2, dof=dof,
                  G_fit=two_inertia_frf(frf.f_hz, *val[:6], output=output, g=g), output=output, gravity_stiffness=g,
                  gravity_stiffness_std=float(std[6]), gravity_fitted=fit_g)
