"""`qualify`: the standard rebound test of a ball (or lining), with its uncertainty [K90 §6].

The default is the ITTF ball test: a 40 mm, 2.7 g ball dropped from 305 mm (its lowest
point above the surface) onto a steel block must rebound 240–260 mm. The test is
simulated with jaxunilat's event mode (the exact Kelvin–Voigt penalty model with
located contacts [K90 Eq. 3.1–3.2], one rigid surface at x = 0, quadratic drag) and the
rebound height is the first free-flight apex after the first impact.

**Uncertainty.** Monte Carlo: parameter draws are pushed through the same event-mode
simulation, and the 95% interval is the 2.5–97.5 percentile range of the simulated
heights (the standard error is their standard deviation).

- When κ and k_r are both identified, (log κ, log k_r) are drawn from the Gaussian with
  the fit's standard errors (relative: sd(log κ) = stderr(κ)/κ) and correlation.
- When only the restitution is identified (apex heights; `identifiable.kappa` false),
  e is drawn from N(e, stderr(e)²) and the contact time t_c log-uniformly from the
  0.5–2 ms prior (`identify._fit._initial.CONTACT_TIME_PRIOR`), and (κ, k_r) follow from the
  inverse Kelvin–Voigt map at the fit's mass. The rebound height depends on t_c only
  through gravity and drag acting during the ~1 ms contact: `tc_sensitivity` reports the
  height change across the prior (about 0.2 mm for the ITTF test, small against the
  20 mm window).

PASS when the 95% interval lies inside [min, max]; FAIL when the estimate (the height at
the point estimate) lies outside; INCONCLUSIVE when the estimate is inside but the
interval crosses a limit.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from jaxunilat._internal import InputError, check_range, latency_bound, shown

from ._fit_json import as_float, check_fit_value, read_json

#: The ITTF ball test: mass (kg), drop height (m), pass window (m), and drag (s/m).
ITTF_MASS = 2.7e-3
ITTF_DROP = 0.305
ITTF_MIN = 0.240
ITTF_MAX = 0.260
DEFAULT_DRAG = 0.12
DEFAULT_GRAVITY = 9.81
DEFAULT_SAMPLES = 1000
#: The contact-time prior used when κ is not identified, s (as `identify._fit._initial.CONTACT_TIME_PRIOR`).
CONTACT_TIME_PRIOR = (0.5e-3, 2.0e-3)
VERDICTS = ("PASS", "FAIL", "INCONCLUSIVE")


@dataclasses.dataclass(frozen=True)
class QualifyResult:
    """The outcome of a rebound test.

    **Fields:**

    - `verdict`: `"PASS"`, `"FAIL"` or `"INCONCLUSIVE"`.
    - `height`: the rebound apex height at the point estimate, m.
    - `stderr`: its standard error, m (0 without uncertainty).
    - `ci95`: the 95% interval `(lo, hi)`, m.
    - `min_height`, `max_height`: the pass window, m.
    - `drop`: the drop height, m. `mass`: kg. `drag`: s/m (0 = none). `gravity`: m/s².
    - `kappa`, `k_r`: the point estimate used, N/m and N·s/m.
    - `restitution`, `contact_time`: their Kelvin–Voigt e and t_c (s) at this mass.
    - `uncertainty`: how the uncertainty was propagated, in words.
    - `samples`: Monte Carlo draws (0: none). `seed`: their seed.
    - `tc_sensitivity`: restitution-only fits: the height change across the 0.5–2 ms
      contact-time prior, m; else `None`.
    - `notes`: warnings (e.g. an unconverged fit).
    """

    verdict: str
    height: float
    stderr: float
    ci95: tuple[float, float]
    min_height: float
    max_height: float
    drop: float
    mass: float
    drag: float
    gravity: float
    kappa: float
    k_r: float
    restitution: float
    contact_time: float
    uncertainty: str
    samples: int
    seed: int | None
    tc_sensitivity: float | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """A JSON-ready dict."""
        d = dataclasses.asdict(self)
        d["ci95"], d["notes"] = list(self.ci95), list(self.notes)
        return d

    def report(self) -> str:
        """A human-readable report, one `key value` line each."""
        lo, hi = self.ci95
        drag = "none (vacuum)" if self.drag == 0 else f"k = {self.drag:g} s/m (--drag 0 for vacuum)"
        if self.verdict == "PASS":
            why = "the 95% interval lies inside"
        elif self.verdict == "FAIL":
            why = "the estimate lies outside"
        else:
            why = "the estimate is inside but the 95% interval crosses a limit of"
        lines = [
            (
                "test",
                f"drop from {self.drop:g} m (lowest point) onto a rigid surface; "
                f"pass window {self.min_height:g}-{self.max_height:g} m",
            ),
            ("ball", f"m = {self.mass:g} kg, g = {self.gravity:g} m/s^2, drag {drag}"),
            (
                "contact",
                f"kappa = {self.kappa:.6g} N/m, k_r = {self.k_r:.6g} N*s/m "
                f"(Kelvin-Voigt e = {self.restitution:.5f}, t_c = {self.contact_time * 1e3:.4g} ms at this mass)",
            ),
            (
                "rebound",
                f"{self.height:.6f} m +- {self.stderr:.2g} m (95% interval {lo:.6f} to {hi:.6f} m)",
            ),
            ("uncertainty", self.uncertainty),
        ]
        if self.tc_sensitivity is not None:
            lines.append(
                (
                    "t_c prior",
                    f"t_c from 0.5 to 2 ms changes the height by {self.tc_sensitivity * 1e3:.3f} mm "
                    "(included in the interval)",
                )
            )
        lines += [("note", n) for n in self.notes]
        lines.append(("verdict", f"{self.verdict} ({why} [{self.min_height:g}, {self.max_height:g}] m)"))
        return "\n".join(f"{k:<12}{v}" for k, v in lines)


def verdict(height: float, ci95: tuple[float, float], min_height: float, max_height: float) -> str:
    """PASS if `ci95` ⊂ [min, max]; FAIL if `height` ∉ [min, max]; else INCONCLUSIVE."""
    lo, hi = ci95
    if not min_height <= height <= max_height:
        return "FAIL"
    if min_height <= lo and hi <= max_height:
        return "PASS"
    return "INCONCLUSIVE"


# -- the simulation ------------------------------------------------------------------------

_REBOUND = {}


def _rebound_fn(has_drag: bool):
    """A jitted (κ, k_r, m, g, k, H) → (rebound height [m], status), one compile per structure."""
    if has_drag in _REBOUND:
        return _REBOUND[has_drag]
    import jax
    import jax.numpy as jnp

    import jaxunilat

    def rebound(kappa, k_r, mass, gravity, drag, drop):
        ball = jaxunilat.Ball(
            kappa=kappa,
            k_r=k_r,
            mass=mass,
            gravity=gravity,
            drag=drag if has_drag else None,
            lower=0.0,
            upper=None,
        )
        # Fall, contact and the rise to the first apex take < 2 drag-free fall times.
        t1 = 3.0 * jnp.sqrt(2.0 * drop / gravity) + 0.01
        sol = jaxunilat.simulate(
            ball,
            jnp.stack([drop, jnp.zeros_like(drop)]),
            t1,
            solver="event",
            rtol=1e-10,
            atol=1e-10,
            samples=2,
            outputs=("x",),
            max_events=64,
            throw=False,
        )
        t_impact = jaxunilat.impact_times(sol, 1)[0]
        t_apex, h_apex = jaxunilat.apexes(sol, 4)
        after = t_apex > t_impact  # NaN compares False
        height = jnp.where(jnp.any(after), h_apex[jnp.argmax(after)], jnp.nan)
        return height, sol.status

    fn = jax.jit(rebound)
    _REBOUND[has_drag] = fn
    return fn


def _heights(kappas, k_rs, *, mass, gravity, drag, drop, statuses: list | None = None) -> np.ndarray:
    """Rebound heights (NaN where none); each run's status is appended to `statuses`."""
    fn = _rebound_fn(drag > 0)
    out = np.empty(len(kappas))
    for i, (kappa, k_r) in enumerate(zip(kappas, k_rs, strict=True)):
        h, status = fn(*(np.float64(v) for v in (kappa, k_r, mass, gravity, drag, drop)))
        out[i] = float(h) if int(status) == 0 else math.nan
        if statuses is not None:
            statuses.append(int(status))
    return out


def _no_rebound(kappa, k_r, drop, status: int) -> InputError:
    """The error for a test run with no rebound height, naming its real cause."""
    if status != 0:
        import jaxunilat

        name = jaxunilat.Status(status).name
        return InputError(
            f"the simulated drop from drop = {drop:g} m failed ({name}) before the first rebound apex; "
            "a rebound test drops from centimetres to a few metres: check drop (m), mass (kg) and gravity"
        )
    return InputError(
        f"kappa = {kappa:g} N/m, k_r = {k_r:g} N*s/m: the ball does not rebound (overdamped contact); "
        "no rebound height"
    )


def rebound_height(
    kappa: float,
    k_r: float,
    *,
    mass: float = ITTF_MASS,
    drop: float = ITTF_DROP,
    drag: float = DEFAULT_DRAG,
    gravity: float = DEFAULT_GRAVITY,
) -> float:
    """The first rebound apex height of a ball dropped from rest, m (event mode, tolerance 1e-10).

    **Arguments:**

    - `kappa`, `k_r`: contact stiffness (N/m, > 0) and damping (N·s/m, ≥ 0), Kelvin–Voigt.
    - `mass`: kg (> 0). `drop`: the release height of the ball's lowest point, m (> 0).
    - `drag`: k = 1/terminal speed, s/m (≥ 0; 0 = vacuum). `gravity`: m/s² (> 0).

    **Returns:** the height of the ball's lowest point at the first apex after the first
    impact, m. Raises `ValueError` if the ball does not rebound (overdamped contact).
    """
    _check_test(mass=mass, drop=drop, drag=drag, gravity=gravity)
    check_range("kappa", kappa, lo=0.0, lo_open=True, unit="N/m")
    check_range("k_r", k_r, lo=0.0, unit="N*s/m")
    statuses: list = []
    (h,) = _heights([kappa], [k_r], mass=mass, gravity=gravity, drag=drag, drop=drop, statuses=statuses)
    if not math.isfinite(h):
        raise _no_rebound(kappa, k_r, drop, statuses[0])
    return h


def _check_test(*, mass, drop, drag, gravity, min_height=0.0, max_height=1.0):
    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg")
    check_range("drop", drop, lo=0.0, lo_open=True, unit="m")
    check_range("drag", drag, lo=0.0, unit="s/m")
    check_range("gravity", gravity, lo=0.0, lo_open=True, unit="m/s^2")
    check_range("min_height", min_height, lo=0.0, unit="m")
    check_range("max_height", max_height, lo=0.0, lo_open=True, unit="m")
    if not min_height < max_height:
        raise InputError(
            f"min_height = {min_height:g} m is not below max_height = {max_height:g} m; "
            "the pass window must be [min, max] with min < max"
        )


def _kv(kappa, k_r, mass):
    """Kelvin–Voigt (e, t_c) of (κ, k_r) at `mass`: e = exp(−πζ/√(1−ζ²)), t_c = π/ω_d."""
    zeta = k_r / (2.0 * math.sqrt(kappa * mass))
    if zeta >= 1:
        return 0.0, math.nan
    omega_d = math.sqrt(kappa / mass) * math.sqrt(1 - zeta**2)
    return math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), math.pi / omega_d


def _from_restitution(e, t_c, mass):
    """The inverse Kelvin–Voigt map, vectorized: κ = m(π² + ln²e)/t_c², k_r = −2 m ln e / t_c."""
    le = np.log(e)
    return mass * (np.pi**2 + le**2) / t_c**2, -2.0 * mass * le / t_c


def _finish(
    height, draws, *, limits, test, kappa, k_r, uncertainty, samples, seed, tc_sensitivity, notes, status=0
):
    if not math.isfinite(height):
        raise _no_rebound(kappa, k_r, test["drop"], status)
    if draws is None:
        stderr, ci = 0.0, (height, height)
    else:
        bad = int(np.sum(~np.isfinite(draws)))
        if bad:
            notes = notes + (f"{bad} of {len(draws)} draws gave no rebound (counted as height 0)",)
            draws = np.where(np.isfinite(draws), draws, 0.0)
        stderr = float(np.std(draws, ddof=1))
        lo, hi = np.percentile(draws, [2.5, 97.5])
        ci = (float(min(lo, height)), float(max(hi, height)))
    e, t_c = _kv(kappa, k_r, test["mass"])
    return QualifyResult(
        verdict=verdict(height, ci, *limits),
        height=float(height),
        stderr=stderr,
        ci95=ci,
        min_height=limits[0],
        max_height=limits[1],
        kappa=float(kappa),
        k_r=float(k_r),
        restitution=e,
        contact_time=t_c,
        uncertainty=uncertainty,
        samples=samples,
        seed=seed,
        tc_sensitivity=tc_sensitivity,
        notes=tuple(notes),
        **test,
    )


def _check_samples(samples, seed):
    if not isinstance(samples, (int, np.integer)) or isinstance(samples, bool) or samples < 20:
        raise InputError(f"samples = {shown(samples)} is out of range; valid range is integers >= 20")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise InputError(f"seed = {shown(seed)} is out of range; valid range is integers >= 0")


def qualify(
    kappa: float,
    k_r: float,
    *,
    stderr: tuple[float, float] | None = None,
    correlation: float = 0.0,
    mass: float = ITTF_MASS,
    drop: float = ITTF_DROP,
    min_height: float = ITTF_MIN,
    max_height: float = ITTF_MAX,
    drag: float = DEFAULT_DRAG,
    gravity: float = DEFAULT_GRAVITY,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
) -> QualifyResult:
    """Simulate the rebound test for contact parameters κ, k_r and give a verdict.

    **Arguments:**

    - `kappa`, `k_r`: contact stiffness (N/m, > 0) and damping (N·s/m, ≥ 0; > 0 with
      `stderr`), e.g. a fit's.
    - `stderr`: their standard errors `(s_kappa, s_k_r)` (N/m, N·s/m), or `None` for
      exact values (no uncertainty; the verdict is then PASS or FAIL).
    - `correlation`: the correlation of the κ and k_r estimates, in [−1, 1].
    - `mass`: the ball, kg (default 2.7e-3, ITTF). `drop`: release height of the ball's
      lowest point, m (default 0.305). `min_height`, `max_height`: the pass window, m
      (default 0.240, 0.260).
    - `drag`: k = 1/terminal speed, s/m (default 0.12; 0 = vacuum). `gravity`: m/s².
    - `samples`: Monte Carlo draws of (log κ, log k_r) (≥ 20; used with `stderr`).
    - `seed`: the seed of `numpy.random.default_rng`.

    **Returns:** a `QualifyResult`.
    """
    _check_test(
        mass=mass, drop=drop, drag=drag, gravity=gravity, min_height=min_height, max_height=max_height
    )
    check_range("kappa", kappa, lo=0.0, lo_open=True, unit="N/m")
    check_range("k_r", k_r, lo=0.0, lo_open=stderr is not None, unit="N*s/m")
    test = dict(mass=float(mass), drop=float(drop), drag=float(drag), gravity=float(gravity))
    limits = (float(min_height), float(max_height))
    statuses: list = []
    (height,) = _heights([kappa], [k_r], **_sim(test), statuses=statuses)
    common = dict(
        limits=limits, test=test, kappa=kappa, k_r=k_r, tc_sensitivity=None, notes=(), status=statuses[0]
    )
    if stderr is None or (stderr[0] == 0 and stderr[1] == 0):
        return _finish(height, None, uncertainty="none (exact parameters)", samples=0, seed=None, **common)
    if len(stderr) != 2:
        raise InputError(f"stderr = {shown(stderr)} must be a pair (s_kappa [N/m], s_k_r [N*s/m])")
    check_range("stderr of kappa", stderr[0], lo=0.0, unit="N/m")
    check_range("stderr of k_r", stderr[1], lo=0.0, unit="N*s/m")
    check_range("correlation", correlation, lo=-1.0, hi=1.0)
    _check_samples(samples, seed)
    s = np.array([stderr[0] / kappa, stderr[1] / k_r])
    cov = np.outer(s, s) * np.array([[1.0, correlation], [correlation, 1.0]])
    draws = _gaussian_draws(np.log([kappa, k_r]), cov, samples, seed)
    heights = _heights(np.exp(draws[:, 0]), np.exp(draws[:, 1]), **_sim(test))
    text = (
        f"Monte Carlo, {samples} draws of (log kappa, log k_r) from a Gaussian with the given standard "
        f"errors and correlation {correlation:.6g}, each simulated (event mode); 95% interval = "
        f"2.5-97.5 percentiles; seed {seed}"
    )
    return _finish(height, heights, uncertainty=text, samples=samples, seed=seed, **common)


def _sim(test):
    return dict(mass=test["mass"], gravity=test["gravity"], drag=test["drag"], drop=test["drop"])


def _gaussian_draws(mean, cov, samples, seed):
    """Draws from N(mean, cov) via the symmetric square root (cov may be singular)."""
    w, v = np.linalg.eigh(cov)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    z = np.random.default_rng(seed).standard_normal((samples, len(mean)))
    return mean + z @ root.T


# -- fit JSON ------------------------------------------------------------------------------


def _number(fit, keys, where, *, required=True, positive=False):
    """`fit[k0][k1]...` as a finite float, `None` (absent/null/non-finite, when not required)."""
    node = fit
    for k in keys:
        node = node.get(k) if isinstance(node, dict) else None
    name = ".".join(keys)
    if node is not None and (isinstance(node, bool) or not isinstance(node, (int, float))):
        # A value of the wrong type is a damaged file, never "absent".
        raise InputError(f"{where}: {name} = {shown(node)} must be a number")
    value = None if node is None else as_float(node)
    if node is not None and value is None:  # an integer beyond float64
        raise InputError(
            f"{where}: {name} = {shown(node)} is out of range; valid range is finite float64 numbers "
            "(magnitude below about 1.8e308)"
        )
    if value is None or not math.isfinite(value):
        if required:
            raise InputError(f"{where}: {name} = {shown(node)} must be a finite number")
        return None
    if positive and not value > 0:
        raise InputError(f"{where}: {name} = {shown(node)} is out of range; valid range is (0, inf)")
    return value


def load_fit(path) -> dict:
    """Read and check a fit JSON written by `jaxunilat identify --json`.

    NaN/Infinity tokens are read as numbers (and then treated as missing where a
    standard error may be missing). Raises `ValueError` naming the file and the entry,
    also for a file nested deeper than a fit's JSON or with a number beyond float64
    (`_fit_json`).
    """
    name = os.fspath(path)
    fit = read_json(name)
    if not isinstance(fit, dict) or not isinstance(fit.get("parameters"), dict):
        raise InputError(
            f"{name}: not a fit JSON: expected an object with 'parameters' "
            "(as written by `jaxunilat identify --json`)"
        )
    return fit


@latency_bound
def qualify_fit(
    fit,
    *,
    mass: float | None = None,
    drop: float = ITTF_DROP,
    min_height: float = ITTF_MIN,
    max_height: float = ITTF_MAX,
    drag: float = DEFAULT_DRAG,
    gravity: float = DEFAULT_GRAVITY,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
) -> QualifyResult:
    """The rebound test for the parameters of a fit (a fit JSON path, or its parsed dict).

    Uses κ and k_r with their standard errors and correlation when the fit identifies
    both; otherwise its restitution with the 0.5–2 ms contact-time prior (see the module
    docstring). `mass` defaults to the fit's `mass` (else 2.7e-3 kg); the other
    arguments are those of `qualify`.
    """
    where = "fit" if isinstance(fit, dict) else os.fspath(fit)
    if not isinstance(fit, dict):
        fit = load_fit(fit)
    fit_mass = _number(fit, ("mass",), where, required=False, positive=True)
    check_fit_value(f"{where}: mass", "mass", fit_mass)
    if mass is None:
        mass = ITTF_MASS if fit_mass is None else fit_mass
    _check_test(
        mass=mass, drop=drop, drag=drag, gravity=gravity, min_height=min_height, max_height=max_height
    )
    _check_samples(samples, seed)
    test = dict(mass=float(mass), drop=float(drop), drag=float(drag), gravity=float(gravity))
    limits = (float(min_height), float(max_height))
    law = fit.get("law", "kelvin-voigt")
    if law != "kelvin-voigt":
        raise InputError(
            f"{where}: law = {shown(law)}: the rebound test is simulated with the Kelvin-Voigt law; "
            "refit with --law kelvin-voigt to qualify"
        )
    ident = fit.get("identifiable")
    if not isinstance(ident, dict) or not all(
        isinstance(ident.get(k), bool) for k in ("kappa", "k_r", "restitution")
    ):
        raise InputError(
            f"{where}: identifiable = {shown(ident)}: expected true/false for kappa, k_r and restitution "
            "(as written by `jaxunilat identify --json`)"
        )
    required = ident["kappa"] and ident["k_r"]
    kappa = _number(fit, ("parameters", "kappa", "value"), where, required=required, positive=True)
    k_r = _number(fit, ("parameters", "k_r", "value"), where, required=required, positive=True)
    s_kappa = _number(fit, ("parameters", "kappa", "stderr"), where, required=False)
    s_k_r = _number(fit, ("parameters", "k_r", "stderr"), where, required=False)
    for name, value, stderr in (("kappa", kappa, s_kappa), ("k_r", k_r, s_k_r)):
        check_fit_value(f"{where}: parameters.{name}.value", name, value)
        if required and value is not None and stderr is not None:
            # Drawn from: beyond 100 times the value the log-normal draws overflow float64.
            unit = "N/m" if name == "kappa" else "N*s/m"
            check_range(f"{where}: parameters.{name}.stderr", stderr, lo=0.0, hi=100 * value, unit=unit)
    notes = ()
    if fit.get("converged") is False:
        notes += ("the fit did not converge (converged = false): the verdict rests on an unconverged fit",)
    both = ident.get("kappa") is True and ident.get("k_r") is True
    if both and None not in (kappa, k_r, s_kappa, s_k_r):
        rho = _correlation(fit, where)
        result = qualify(
            kappa,
            k_r,
            stderr=(s_kappa, s_k_r),
            correlation=rho,
            samples=samples,
            seed=seed,
            min_height=min_height,
            max_height=max_height,
            **test,
        )
        return dataclasses.replace(
            result,
            uncertainty=result.uncertainty.replace("the given", "the fit's"),
            notes=result.notes + notes,
        )
    e = _number(fit, ("derived", "restitution", "value"), where, required=False)
    s_e = _number(fit, ("derived", "restitution", "stderr"), where, required=False)
    if ident.get("restitution") is not True or e is None or s_e is None:
        raise InputError(
            f"{where}: the fit identifies neither kappa and k_r (identifiable.kappa/k_r with finite "
            "stderr) nor the restitution (identifiable.restitution with derived.restitution value and "
            "stderr); nothing to qualify"
        )
    if not 0 < e < 1:
        raise InputError(
            f"{where}: derived.restitution.value = {shown(e)} is out of range; valid range is (0, 1)"
        )
    check_range(f"{where}: derived.restitution.stderr", s_e, lo=0.0, hi=1.0)
    if fit_mass is None:
        raise InputError(
            f"{where}: mass is missing; a restitution-only fit needs the mass it was fitted at (kg)"
        )
    lo_tc, hi_tc = CONTACT_TIME_PRIOR
    t_c0 = math.sqrt(lo_tc * hi_tc)
    kappa0, k_r0 = _from_restitution(e, t_c0, fit_mass)
    ends = _heights(*_from_restitution(e, np.array([lo_tc, hi_tc]), fit_mass), **_sim(test))
    (height,) = _heights([kappa0], [k_r0], **_sim(test))
    rng = np.random.default_rng(seed)
    es = e + s_e * rng.standard_normal(samples)
    es = np.clip(es, 1e-6, 1.0 - 1e-9)
    tcs = np.exp(rng.uniform(math.log(lo_tc), math.log(hi_tc), samples))
    heights = _heights(*_from_restitution(es, tcs, fit_mass), **_sim(test))
    text = (
        f"Monte Carlo, {samples} draws: the fit identifies only the restitution, so e ~ N({e:.6g}, "
        f"{s_e:.3g}^2) and t_c log-uniform on the 0.5-2 ms prior, mapped to (kappa, k_r) at the fit's "
        f"mass {fit_mass:g} kg and simulated (event mode); 95% interval = 2.5-97.5 percentiles; seed {seed}"
    )
    return _finish(
        height,
        heights,
        limits=limits,
        test=test,
        kappa=float(kappa0),
        k_r=float(k_r0),
        uncertainty=text,
        samples=samples,
        seed=seed,
        tc_sensitivity=float(abs(ends[1] - ends[0])),
        notes=notes,
    )


def _correlation(fit, where) -> float:
    """The κ–k_r correlation: entry [0][1] of `correlation` (order kappa, k_r, then any nuisance)."""
    corr = fit.get("correlation")
    try:
        c = np.array(corr, dtype=float)
    except (TypeError, ValueError, OverflowError):
        c = None
    if c is None or c.ndim != 2 or c.shape[0] != c.shape[1] or c.shape[0] < 2 or not np.all(np.isfinite(c)):
        raise InputError(
            f"{where}: correlation = {shown(corr)} must be a square matrix (at least 2x2, order kappa, k_r, ...) "
            "of finite numbers"
        )
    if (
        np.any(np.abs(c - c.T) > 1e-6)
        or np.any(np.abs(np.diag(c) - 1) > 1e-6)
        or np.any(np.abs(c) > 1 + 1e-9)
    ):
        raise InputError(
            f"{where}: correlation = {shown(corr)} is not a correlation matrix (symmetric, unit diagonal, |rho| <= 1)"
        )
    return float(np.clip(c[0, 1], -1.0, 1.0))
