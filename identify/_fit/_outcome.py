"""What a finished fit is, in numbers: `FitOutcome`, frozen and typed, and its parts.

The fit layer builds a `FitOutcome` (`_summary.summarize_fit`) and derives the next one
from it where a later stage says more (the profile of κ, the closed-form gate, a restart,
the files' own clocks); nothing is changed in place. `identify.FitResult`
(`identify._report._result`) is the same record with its report and JSON views, built
once at the end of `identify.fit`.

Mappings are read-only views, sequences tuples and arrays read-only, so a result cannot
be changed after it is built (use `dataclasses.replace` for a variant).
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from typing import Any

import jax.numpy as jnp
import numpy as np

import jaxunilat as ju

from .._data._format import Dataset
from ._estimate import Estimate
from ._joint import Layout
from ._problem import LAW_MODELS, NEUTRAL, from_z, units

#: The quantities with an identifiability verdict, in the order the report and JSON list them.
VERDICTS = ("kappa", "k_r", "restitution", "contact_time")
#: The quantities that carry the contact's time scale: κ, k_r and t_c (e does not need it).
CONTACT = ("kappa", "k_r", "contact_time")


def frozen(value):
    """`value` with its dicts as read-only mappings and its lists as tuples, nested."""
    if isinstance(value, Mapping):
        return types.MappingProxyType({k: frozen(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value


def _read_only(array) -> np.ndarray | None:
    """`array` as a read-only NumPy array (a copy where it was writeable)."""
    if array is None:
        return None
    out = np.asarray(array)
    if out.flags.writeable:
        out = out.copy()
        out.setflags(write=False)
    return out


@dataclasses.dataclass(frozen=True)
class Outlier:
    """A row the robust pass excluded: its 0-based `row`, its time `t` (s; None for apex
    heights without times), its `residual` (prediction − data, s for onsets, m otherwise)
    and the `reason`."""

    row: int
    t: float | None
    residual: float
    reason: str


@dataclasses.dataclass(frozen=True)
class MissedBounce:
    """An interval of impact onsets that spans an unheard bounce: between 0-based rows
    `after_row` and `before_row`, `interval` s after an interval of `previous` s."""

    after_row: int
    before_row: int
    interval: float
    previous: float


@dataclasses.dataclass(frozen=True)
class FileFit:
    """One file of a fit: its rows, outliers, missed bounces, scatter and own entries.

    - `data`: the file's path (None for data held in memory); `observe`: its kind.
    - `rows`, `used` (fitted), `held_out`: row counts.
    - `outliers`, `missed`: the excluded rows and the unheard bounces (impact onsets).
    - `rms`: the residual rms of the used rows, s for onsets, m otherwise (None: none used).
    - `sigma`: the noise σ used for this file (same unit; the relative scatter of e under
      the restitution-scatter model).
    - `params`: the file's own fitted entries (x0 m, v0 m/s, offset s, a trace's scale
      and level m), `Estimate`s from the joint covariance.
    - `restitution_alone`: the file's own e, κ and k_r fitted to it alone (a joint fit of
      several files), else None.
    """

    data: str | None
    observe: str
    rows: int
    used: int
    held_out: int
    outliers: tuple[Outlier, ...] = ()
    missed: tuple[MissedBounce, ...] = ()
    rms: float | None = None
    sigma: float = math.nan
    params: Mapping[str, Estimate] = dataclasses.field(default_factory=dict)
    restitution_alone: Estimate | None = None

    def __post_init__(self):
        object.__setattr__(self, "outliers", tuple(self.outliers))
        object.__setattr__(self, "missed", tuple(self.missed))
        object.__setattr__(self, "params", types.MappingProxyType(dict(self.params)))

    def to_json(self) -> dict:
        """The file's entry of the JSON's `datasets` (its own entries under `parameters`)."""
        return {
            "data": self.data,
            "observe": self.observe,
            "rows": self.rows,
            "used": self.used,
            "held_out": self.held_out,
            "outliers": [dataclasses.asdict(o) for o in self.outliers],
            "missed": [dataclasses.asdict(m) for m in self.missed],
            "rms": self.rms,
            "sigma": self.sigma,
            "parameters": {name: e.to_json() for name, e in self.params.items()},
            "restitution_alone": None if self.restitution_alone is None else self.restitution_alone.to_json(),
        }


@dataclasses.dataclass(frozen=True)
class StartRun:
    """One start of the fit: its final `cost` (½χ² on the first window), whether it
    `converged`, and where it ended (`z`, the joint vector)."""

    cost: float
    converged: bool
    z: np.ndarray | None = None


@dataclasses.dataclass(frozen=True)
class InitialGuess:
    """The closed-form start: `restitution` e, `contact_time` t_c (s), and the `source`
    of e in words (e.g. "closed form (flight times)")."""

    restitution: float
    contact_time: float
    source: str


@dataclasses.dataclass(frozen=True, eq=False)
class Profile:
    """The profile likelihood of κ (`_profile.profile_kappa`).

    - `kappa`: the grid of κ (the law's unit); `delta_chi2`: Δχ² at each point;
      `costs`: each point's ½χ² (None where not kept).
    - `ci95`: the 95% interval of κ where Δχ² ≤ 3.84 (0 or inf: open on that side; NaN:
      a re-fit next to that end failed).
    - `failed`: the κ whose re-fit failed (never taken as excluded).
    - `value`: the fitted κ; `unit`: κ's unit.
    - `below_fit`: how far (χ²) the profile reached below the fit's own minimum, or None.
    """

    kappa: np.ndarray
    delta_chi2: np.ndarray
    ci95: tuple[float, float]
    value: float
    unit: str = "N/m"
    costs: np.ndarray | None = None
    failed: tuple[float, ...] = ()
    below_fit: float | None = None

    def __post_init__(self):
        for name in ("kappa", "delta_chi2", "costs"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))
        object.__setattr__(self, "ci95", tuple(float(v) for v in self.ci95))
        object.__setattr__(self, "failed", tuple(float(v) for v in self.failed))

    @property
    def bound(self):
        """What the profile bounds of κ (`_estimate.bound` of its interval)."""
        from ._estimate import bound

        return bound("kappa", self.value, self.ci95, self.unit)


@dataclasses.dataclass(frozen=True)
class Restart:
    """A restart from the closed form after the first fit contradicted it: the first
    fit's e (`first_restitution`), why it was contradicted (`reasons`), and whether the
    restart's result was taken (`accepted`)."""

    first_restitution: float
    reasons: tuple[str, ...]
    accepted: bool

    def __post_init__(self):
        object.__setattr__(self, "reasons", tuple(self.reasons))


@dataclasses.dataclass(frozen=True, eq=False)
class FitOutcome:
    """The outcome of a fit, in numbers (`identify.FitResult` adds its report and JSON).

    **Fields:**

    - `params`: `{name: Estimate}` for kappa (N/m), k_r (N·s/m) (Hunt–Crossley: N/m^1.5,
      N·s/m^2.5), drag (s/m), x0 (m), v0 (m/s), offset (s), and a trace's scale (data per
      model length) and level (m), SI units: file 0's view of the joint vector (the shared
      contact parameters and file 0's own entries); a parameter that was not fitted is
      `fixed`, stderr 0, at the file's or the initial value.
    - `derived`: the same for `restitution` (e, Kelvin–Voigt, [K90 Eq. 3.1]) and
      `contact_time` (t_c = π/ω_d, s).
    - `withheld`: `{name: reason}` for each of κ, k_r, e, t_c whose own interval would
      pass but that is not identifiable for a reason of the whole fit (an inconsistent
      fit, a profile of κ open on one side).
    - `goodness`: `{"reduced_chi2", "dof", "p_value", "consistent"}`, the χ² test of the
      fit against the file's noise σ (p_value and consistent None when σ was estimated).
    - `correlation`: the correlation matrix of the fitted entries of z (logs for κ, k_r,
      drag), in the order `free`.
    - `converged`, `message`, `iterations` (LM), `gradient_steps` (optax stage), `method`.
    - `cost` (½χ² of the fitted rows), `chi2`: Σ((prediction − data)/σ)²; `sigma`: the noise
      σ used for the uncertainty (from the file, or estimated from the residuals:
      `sigma_source`). Under the restitution-scatter model of impact onsets (`sigma_source`
      = "restitution scatter") the fitted rows are log ratios of successive flights,
      `chi2` is theirs and `sigma` is the relative bounce-to-bounce variation of e.
    - `residuals`: prediction − data, in the data's units (s or m), every file's rows;
      `used`: the fitted rows (outliers and held-out rows not); `row_sigma`: each row's σ.
    - `starts`: every start (`StartRun`); `initial`: the closed-form start; `profile`: the
      profile likelihood of κ (asked for, or computed to confirm an identifiable κ).
    - `law`, `laws`, `law_choice`: the contact law's name, and with `law="auto"` each law's
      χ², AIC, BIC and estimates on the rows both used (`criteria`).
    - `datasets`: one `FileFit` per file; `datasets_data` the files themselves (`data`:
      file 0).
    - `noise`: the stated σ against the residual scatter, in words (`noise["text"]`) and a
      `verdict`.
    - `holdout`: `{"fraction", "rows", "rms", "max", "within_noise", …}` in data units.
    - `robust`: the robust pass's loss, threshold and scale (None with keep_outliers).
    - `trends`: one mapping per file whose own flights show e changing with the impact
      speed (`direction`, the splitting `speed` m/s, `e_above`, `e_below`, `z`, `bounces`,
      `rows_used` (first and last fitted row, 0-based), `rows`); JSON `restitution_trend`.
    - `restart`: a `Restart` where the first fit contradicted the data's closed form.
    - `contradictions`: why the fit contradicts its data's closed form (none: empty).
    - `notes`: what the fit and the data's checks want the reader to know.
    - `simulations`: compiled evaluations (each 2q + 1 event-mode runs, q the free
      parameters other than the offset); `wall_s`: the fit's wall time, s.
    - `z`: file 0's vector (`PARAMETERS`, logs for κ, k_r, drag); `joint_z`: every file's;
      `problem`: file 0's `Problem`; `n_parameters`: the free entries of the joint fit;
      `sigma_known`: whether σ is the files' stated noise; `rel_halfwidth`: the
      identifiability threshold (95% half-width / value).
    """

    data: Dataset
    problem: Any
    z: np.ndarray
    free: tuple[str, ...]
    params: Mapping[str, Estimate]
    derived: Mapping[str, Estimate]
    correlation: np.ndarray
    cost: float
    residuals: np.ndarray
    chi2: float
    sigma: float
    sigma_source: str
    goodness: Mapping[str, Any]
    converged: bool
    message: str
    iterations: int
    gradient_steps: int
    method: str
    starts: tuple[StartRun, ...]
    initial: InitialGuess
    profile: Profile | None
    rel_halfwidth: float
    simulations: int
    wall_s: float
    law: str = "kelvin-voigt"
    datasets: tuple[FileFit, ...] = ()
    used: np.ndarray | None = None
    noise: Mapping[str, Any] | None = None
    holdout: Mapping[str, Any] | None = None
    robust: Mapping[str, Any] | None = None
    n_parameters: int = 2
    joint_z: np.ndarray | None = None
    laws: Mapping[str, Mapping[str, Any]] | None = None
    law_choice: str = "given"
    row_sigma: np.ndarray | None = None
    sigma_known: bool = False
    datasets_data: tuple[Dataset, ...] = ()
    notes: tuple[str, ...] = ()
    contradictions: tuple[str, ...] = ()
    withheld: Mapping[str, str] = dataclasses.field(default_factory=dict)
    trends: tuple[Mapping[str, Any], ...] = ()
    restart: Restart | None = None

    def __post_init__(self):
        for name in ("z", "correlation", "residuals", "used", "joint_z", "row_sigma"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))
        for name in ("free", "starts", "datasets", "datasets_data", "notes", "contradictions"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        for name in ("params", "derived"):
            object.__setattr__(self, name, types.MappingProxyType(dict(getattr(self, name))))
        for name in ("goodness", "noise", "holdout", "robust", "laws", "withheld", "trends"):
            object.__setattr__(self, name, frozen(getattr(self, name)))

    @property
    def identifiable(self) -> Mapping[str, bool]:
        """`{kappa, k_r, restitution, contact_time}` → bool: a finite 95% CI whose
        half-width is at most `rel_halfwidth` of the value, in a converged fit that its
        data do not contradict. κ, k_r and t_c also need a fit consistent with its noise
        (the χ² test of `goodness`) and a profile likelihood of κ that closes on both
        sides (`profile`); `withheld` says why one of them is not, where its interval
        alone would have passed."""
        return types.MappingProxyType({name: bool(self.estimate(name).identifiable) for name in VERDICTS})

    def estimate(self, name: str) -> Estimate:
        """The `Estimate` of a parameter (`params`) or a derived quantity (`derived`)."""
        return self.derived[name] if name in self.derived else self.params[name]

    @property
    def kappa(self) -> float:
        """κ, N/m (the law's unit)."""
        return self.params["kappa"].value

    @property
    def k_r(self) -> float:
        """k_r, N·s/m (the law's unit)."""
        return self.params["k_r"].value

    @property
    def law_model(self) -> ju.AbstractContactLaw:
        """The contact law's object (`jaxunilat.KelvinVoigt`, `jaxunilat.HuntCrossley`)."""
        return LAW_MODELS[self.law]

    @property
    def units(self) -> dict[str, str]:
        """Every parameter's unit under the fit's law."""
        return units(self.law)

    def values(self) -> dict[str, float]:
        """Every parameter's value (`PARAMETERS`), SI units."""
        return from_z(self.z)

    def file_values(self) -> list[dict[str, float]]:
        """Each file's entries (`PARAMETERS`) as the fit used them (fitted or held), SI units."""
        datasets = self.datasets_data or (self.data,)
        n_files = len(datasets)
        if self.joint_z is not None:
            layout = Layout(n_files=n_files)
            if self.joint_z.size == layout.size:
                return [
                    from_z(np.asarray(self.joint_z, dtype=float)[layout.index[f]]) for f in range(n_files)
                ]
        if n_files == 1:
            return [from_z(self.z)]
        return [{"x0": float(d.x0), "v0": float(d.v0), "offset": 0.0, **NEUTRAL} for d in datasets]

    def kappa_k_r_correlation(self) -> float:
        """corr(log κ, log k_r) of the estimates (NaN unless both were fitted)."""
        if "kappa" in self.free and "k_r" in self.free:
            return float(self.correlation[self.free.index("kappa"), self.free.index("k_r")])
        return math.nan

    def ball(self) -> ju.Ball:
        """The fitted `jaxunilat.Ball` (exact Heaviside) for this data set's scene."""
        return self.problem.ball(jnp.asarray(self.z))

    def criteria(self, used: np.ndarray | None = None) -> dict:
        """χ², AIC and BIC of the fit over the `used` rows (default: its fitted rows).

        With the files' noise σ: χ² = Σ(r/σ)², AIC = χ² + 2p, BIC = χ² + p ln n; without
        it, χ² is replaced by n ln(RSS/n) (the Gaussian likelihood at the estimated σ).
        Two laws are compared on the same rows (`fit(law="auto")` passes the rows both
        used).
        """
        used = self.used if used is None else used
        sigma = self.row_sigma if self.row_sigma is not None else np.ones_like(self.residuals)
        r = (self.residuals / sigma)[used]
        n, p = int(r.size), int(self.n_parameters)
        chi2 = float(np.sum(r**2))
        fit_term = chi2 if self.sigma_known else n * math.log(max(chi2 / max(n, 1), 1e-300))
        return {
            "chi2": chi2,
            "n": n,
            "p": p,
            "aic": fit_term + 2 * p,
            "bic": fit_term + p * math.log(max(n, 1)),
            "parameters": {k: self.params[k].value for k in ("kappa", "k_r")},
            "restitution": self.derived["restitution"].value,
            "contact_time": self.derived["contact_time"].value,
            "converged": bool(self.converged),
        }

    def with_verdicts(self, verdicts: Mapping[str, bool]) -> FitOutcome:
        """This outcome with the identifiability of the quantities in `verdicts` replaced."""
        params, derived = dict(self.params), dict(self.derived)
        for name, verdict in verdicts.items():
            table = derived if name in derived else params
            table[name] = dataclasses.replace(table[name], identifiable=bool(verdict))
        return dataclasses.replace(self, params=params, derived=derived)

    def nothing_identifiable(self, **changes) -> FitOutcome:
        """This outcome with no quantity identifiable (and `changes`, e.g. a message)."""
        return dataclasses.replace(self.with_verdicts(dict.fromkeys(VERDICTS, False)), **changes)

    def withhold(self, names, reason: str) -> FitOutcome:
        """This outcome with `names` not identifiable, giving `reason` for those whose own
        interval passed (`withheld`)."""
        passed = [name for name in names if self.identifiable[name]]
        if not passed:
            return self
        withheld = {**self.withheld, **{name: reason for name in passed if name not in self.withheld}}
        return dataclasses.replace(self.with_verdicts(dict.fromkeys(passed, False)), withheld=withheld)

    def noted(self, *notes: str) -> FitOutcome:
        """This outcome with `notes` added after its own."""
        return dataclasses.replace(self, notes=(*self.notes, *notes)) if notes else self
