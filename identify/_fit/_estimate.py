"""One estimated quantity of a fit (`Estimate`), and what its data bound of it (`Bound`).

Every quantity a fit reports, fitted or derived, is an `Estimate`: its value, standard
error and 95% interval in SI units (κ and k_r in the contact law's units), whether it was
held, its identifiability verdict where it has one, and `bound`, what the data bound of it
(a 95% interval whose ends are absurd or decades apart bounds nothing useful).
"""

from __future__ import annotations

import dataclasses
import math

from jaxunilat._internal import finite_or_none

from ._problem import LOG_PARAMETERS

#: A 95% interval whose ends lie more than this many decades apart bounds nothing useful.
SPAN_DECADES = 3.0
#: An interval end beyond 1e±30 (SI units) is a number, not a bound.
ABSURD = 1e30
#: Contact times outside this window (s) are no physical bound on a ball's contact.
CONTACT_TIME_WINDOW = (1e-6, 1.0)
#: The quantities `bound` applies to: (symbol, scale from SI, unit shown; None: the law's
#: unit) and their SI unit (κ and k_r under Kelvin–Voigt).
_SHOWN = {
    "kappa": ("kappa", 1.0, None, "N/m"),
    "k_r": ("k_r", 1.0, None, "N*s/m"),
    "drag": ("drag", 1.0, "s/m", "s/m"),
    "restitution": ("e", 1.0, "", ""),
    "contact_time": ("t_c", 1e3, "ms", "s"),
}
#: The quantities that have a `Bound`.
BOUNDED = tuple(_SHOWN)


@dataclasses.dataclass(frozen=True)
class Bound:
    """What the data bound of one quantity (`bound`).

    - `kind`: "interval" (both ends), "upper" (only an upper limit), "lower" (only a
      lower limit) or "none" (not bounded by the data).
    - `lower`, `upper`: the surviving ends, SI units (None where dropped).
    - `unit`: the SI unit of the ends (κ and k_r: the Kelvin–Voigt units N/m, N·s/m).
    - `text`: the readable statement, e.g. "95% CI [0.96, 0.97]", "t_c < 3.2 ms (no lower
      bound from the data)" or "not bounded by the data (95% CI spans 4.2 decades)".
    """

    kind: str
    lower: float | None
    upper: float | None
    unit: str
    text: str

    def to_json(self) -> dict:
        """`{"kind", "lower", "upper", "unit", "text"}`."""
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """One quantity of a fit, SI units (κ and k_r in the law's units, `unit`).

    - `name`: the quantity (`kappa`, `k_r`, `drag`, `x0`, `v0`, `offset`, `scale`,
      `level`, `restitution`, `contact_time`).
    - `value`: the estimate (or the held value).
    - `stderr`: its standard error, same unit: 0 for a held value, inf where the data
      leave it unbounded. κ, k_r, drag and t_c: value × sd(log value).
    - `ci95`: the 95% interval (lower, upper), same unit: exp(log value ± 1.96 sd) for the
      positive quantities, value ± 1.96 sd otherwise (e clipped to [0, 1]); (value,
      value) for a held value, (−inf, inf) where unbounded.
    - `unit`: "N/m", "N*s/m" (Kelvin–Voigt; Hunt–Crossley "N/m^1.5", "N*s/m^2.5"), "s/m",
      "m", "m/s", "s", "" (scale, e).
    - `fixed`: held at its value, not fitted.
    - `identifiable`: the verdict of κ, k_r, e and t_c (`FitOutcome.identifiable`); None
      for the nuisance parameters, which have none.
    - `bound` (a property): what the data bound of κ, k_r, drag, e and t_c (`bound`);
      None for the others.
    """

    name: str
    value: float
    stderr: float
    ci95: tuple[float, float]
    unit: str = ""
    fixed: bool = False
    identifiable: bool | None = None

    def __post_init__(self):
        lo, hi = self.ci95
        object.__setattr__(self, "ci95", (float(lo), float(hi)))

    @property
    def bound(self) -> Bound | None:
        """What the data bound of this quantity (`bound`); None for a quantity without one."""
        if self.name not in BOUNDED:
            return None
        return bound(self.name, self.value, self.ci95, self.unit or None)

    def to_json(self) -> dict:
        """`{"value", "stderr", "ci95"}`, with None for each number that is not finite."""
        return {
            "value": finite_or_none(self.value),
            "stderr": finite_or_none(self.stderr),
            "ci95": [finite_or_none(v) for v in self.ci95],
        }


def estimate(name: str, entry: dict, unit: str = "", *, fixed: bool = False, identifiable=None) -> Estimate:
    """The `Estimate` of an entry `{"value", "stderr", "ci95"}` (as `_uncertainty.summarize`
    writes them)."""
    return Estimate(
        name=name,
        value=float(entry["value"]),
        stderr=float(entry["stderr"]),
        ci95=tuple(entry["ci95"]),
        unit=unit,
        fixed=fixed,
        identifiable=None if identifiable is None else bool(identifiable),
    )


def bound(name: str, value: float, ci95, unit: str | None = None) -> Bound:
    """What the data bound of one quantity, from its 95% interval `ci95` (SI units).

    An end says nothing when it is not finite, is at or beyond 1e±30, is ≤ 0 for a
    positive quantity (κ, k_r, drag, t_c), lies outside 1 µs–1 s for the contact time
    t_c, or (e) is the clip at 0 or 1. When both ends survive but lie more than
    `SPAN_DECADES` decades apart, or one survives more than that far from the estimate,
    neither is a useful bound either.

    **Arguments:** `name` (kappa, k_r, drag, restitution, contact_time), the estimate's
    `value`, its `ci95`, and the unit to show κ and k_r in (the law's; default N/m,
    N·s/m).
    """
    symbol, scale, shown, si = _SHOWN.get(name, (name, 1.0, "", ""))
    shown = (unit or si) if shown is None else shown
    lo, hi = (float(v) for v in ci95)
    value = float(value)
    positive = name in LOG_PARAMETERS or name == "contact_time"
    keep_lo, keep_hi = _usable(name, lo, positive), _usable(name, hi, positive)
    span = None
    if positive and keep_lo and keep_hi:
        span = math.log10(hi / lo)
        if span > SPAN_DECADES:
            keep_lo = keep_hi = False
    elif positive and value > 0 and math.isfinite(value):
        far = [lo, hi][keep_hi] if keep_lo != keep_hi else None
        if far is not None and abs(math.log10(far / value)) > SPAN_DECADES:
            keep_lo = keep_hi = False
    if name == "restitution" and (keep_lo or keep_hi):
        keep_lo = keep_hi = math.isfinite(lo) and math.isfinite(hi)
    if not positive and name != "restitution":
        keep_lo = keep_hi = keep_lo and keep_hi

    def fmt(v: float) -> str:
        return f"{v * scale:.3g}" + (f" {shown}" if shown else "")

    if keep_lo and keep_hi:
        kind = "interval"
        text = f"95% CI [{lo * scale:.6g}, {hi * scale:.6g}]" + (f" {shown}" if shown else "")
    elif keep_hi:
        kind, text = "upper", f"{symbol} < {fmt(hi)} (95%; no lower bound from the data)"
    elif keep_lo:
        kind, text = "lower", f"{symbol} > {fmt(lo)} (95%; no upper bound from the data)"
    else:
        if span is not None:
            why = f"95% CI spans {span:.1f} decades"
        elif name == "restitution" and math.isfinite(lo) and math.isfinite(hi):
            why = "95% CI covers 0 to 1"
        else:
            why = "95% CI unbounded"
        kind, text = "none", f"not bounded by the data ({why})"
    return Bound(kind=kind, lower=lo if keep_lo else None, upper=hi if keep_hi else None, unit=si, text=text)


def _usable(name: str, end: float, positive: bool) -> bool:
    """Whether one end of a 95% interval says something (see `bound`)."""
    if not math.isfinite(end) or abs(end) >= ABSURD:
        return False
    if name == "restitution":
        return 0.0 < end < 1.0
    if positive:
        if end <= 1.0 / ABSURD:
            return False
        if name == "contact_time" and not CONTACT_TIME_WINDOW[0] <= end <= CONTACT_TIME_WINDOW[1]:
            return False
    return True
