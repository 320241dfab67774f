"""Export identified contact parameters to MuJoCo (`solref`, `solimp`).

The ball's contact law [K90 Eq. 3.2] is a linear spring–damper switched on in
contact, F = κδ + k_r δ̇. MuJoCo's soft contact (Modeling chapter, "Solver
parameters") makes the normal acceleration of a contact approximately

    a = d·(−b·v − k·r) + (1 − d)·a₀

where r is the signed distance (r < 0 in penetration), v its rate, a₀ the
acceleration without the contact, d the impedance set by `solimp`, and k, b come
from `solref`. MuJoCo documents two formats for `solref`, with d_width =
`solimp[1]` (= d_max):

- direct, `solref="−stiffness −damping"`: b = damping/d_width,
  k = stiffness·d(r)/d_width²;
- standard, `solref="timeconst dampratio"`: b = 2/(d_width·timeconst),
  k = d(r)/(d_width²·timeconst²·dampratio²).

With a constant impedance d(r) = d_0 = d_width (the exported `solimp` sets
d_0 = d_max), the effective stiffness d·k and damping d·b are

- direct: stiffness and damping themselves, in acceleration units (1/s², 1/s):
  so stiffness = κ/m and damping = k_r/m. Passing κ and k_r unnormalized is the
  classic mistake (e ≈ 0.997 and t_c ≈ 31 ms instead of 0.94 and 1.6 ms for a
  2.7 g ball);
- standard: 1/(timeconst·dampratio)² and 2/timeconst, so timeconst = 2m/k_r and
  dampratio = k_r/(2√(κm)) = ζ, the Kelvin–Voigt damping ratio. d_max cancels
  (it scales k and b of both formats alike), so the standard pair is exactly the
  direct pair in other units.

Both formats give MuJoCo the same contact, which is the Kelvin–Voigt law with one
difference: a MuJoCo contact force cannot pull. The paper's law pulls briefly
before separation (`jaxunilat.KelvinVoigt`), MuJoCo's releases the ball when the force reaches
zero, so MuJoCo's rebound is slightly more elastic. Without gravity this
non-adhesive law has a closed form (`nonadhesive_rebound`): e = 0.94202 instead
of the Kelvin–Voigt 0.94132 at κ = 1e4 N/m, k_r = 0.2 N·s/m, m = 2.7 g, and the
difference grows with ζ (about +4e-3 at ζ = 0.043, +1.4e-2 at ζ = 0.096).
`match="rebound"` inverts the closed form: it picks the stiffness and damping
whose non-pulling contact rebounds with the fitted e and t_c.

Also in MuJoCo: a fraction 1 − d of the other forces (gravity) acts during
contact, against all of it in the paper's model (a difference below 5e-4 in e
for impacts faster than 1 m/s); with the default pyramidal friction cone the
normal response matches only for sliding friction 1 (use `cone="elliptic"` or
`condim="1"` otherwise); MuJoCo averages standard-format `solref` and `solimp`
of two geoms of equal priority, hence `priority="1"` in the snippet.

The mapping assumes that the ball's mass m is the effective mass of the contact
(a ball on a fixed or much heavier surface). Between two moving bodies of masses
m₁ and m₂ the effective mass is the reduced mass m₁m₂/(m₁ + m₂): pass it as
`mass`. The fit's κ and k_r (N/m, N·s/m) are then kept and e and t_c change.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, NamedTuple

from jaxunilat._internal import InputError, check_choice, check_range, printable, shown

from ._fit_json import check_fit_value, finite_number, parse_json

MODES = ("direct", "standard")
MATCHES = ("law", "rebound")

#: Impedance d_0 = d_max of the exported `solimp` (constant: width, midpoint and power unused).
DEFAULT_IMPEDANCE = 0.99

#: MuJoCo clamps the impedance to [mjMINIMP, mjMAXIMP] = [0.0001, 0.9999].
_MIN_IMP, _MAX_IMP = 1e-4, 0.9999

_Z95 = 1.959963984540054  # two-sided 95% normal quantile


class Estimate(NamedTuple):
    """A value with its standard error and 95% interval (either may be `None`)."""

    value: float
    stderr: float | None = None
    ci95: tuple[float, float] | None = None


# -- Kelvin–Voigt relations in plain floats -------------------------------------------


def _zeta_from_e(e: float) -> float:
    """ζ = −ln e / √(π² + ln²e), the inverse of e = exp(−πζ/√(1 − ζ²))."""
    le = math.log(e)
    return -le / math.sqrt(math.pi**2 + le**2)


def _dzeta_de(e: float) -> float:
    le = math.log(e)
    return -(math.pi**2) / (math.pi**2 + le**2) ** 1.5 / e


def _e_from_zeta(zeta: float) -> float:
    if zeta >= 1:
        return 0.0
    return math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta**2))


def nonadhesive_rebound(zeta: float) -> tuple[float, float]:
    """Rebound of a Kelvin–Voigt contact whose force cannot pull (MuJoCo's contact).

    A mass hits a wall at speed v without gravity; in contact its penetration δ
    follows δ̈ + 2ζω δ̇ + ω²δ = 0 until the repulsive force κδ + k_r δ̇ reaches
    zero (at ω_d t_s = π − atan(2ζ√(1 − ζ²)/(1 − 2ζ²))); the body then leaves at
    constant speed and crosses the wall's surface at t_c.

    **Arguments:**

    - `zeta`: the damping ratio ζ = k_r/(2√(κm)), in [0, 1/√2).

    **Returns:** `(e, ω t_c)`: the restitution |v_out/v_in| and the geometric
    contact time in units of 1/ω = √(m/κ) (π for ζ = 0).
    """
    check_range("zeta", zeta, lo=0.0, hi=1.0 / math.sqrt(2.0), hi_open=True)
    s = math.sqrt(1.0 - zeta**2)
    theta = math.atan2(2.0 * zeta * s, -(1.0 - 2.0 * zeta**2))  # ω_d t_s, in (π/2, π]
    t_s = theta / s  # in units of 1/ω
    decay = math.exp(-zeta * t_s)
    delta = decay * math.sin(theta) / s  # δ(t_s) for unit impact speed and ω = 1
    rate = decay * (math.cos(theta) - zeta / s * math.sin(theta))  # δ̇(t_s) < 0
    return -rate, t_s + delta / -rate


# -- reading the fit --------------------------------------------------------------------


def _load(fit_or_path) -> tuple[dict, str | None]:
    if isinstance(fit_or_path, (str, os.PathLike)):
        path = os.fspath(fit_or_path)
        if os.path.isdir(path):
            raise InputError(f"fit file {path!r} is a directory, not a JSON file")
        try:
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
        except FileNotFoundError:
            raise InputError(
                f"fit file {path!r} not found; write it with `jaxunilat identify --json`"
            ) from None
        except UnicodeDecodeError as err:
            raise InputError(f"fit file {path!r} is not valid JSON ({err})") from None
        except OSError as err:
            raise InputError(f"fit file {path!r} cannot be read ({err.strerror or err})") from None
        try:
            return parse_json(text), path
        except InputError as err:
            raise InputError(f"fit file {path!r} is not valid JSON: {err}") from None
    if hasattr(fit_or_path, "to_json_dict"):
        return fit_or_path.to_json_dict(), None
    if isinstance(fit_or_path, dict):
        return fit_or_path, None
    raise InputError(
        f"fit = {type(fit_or_path).__name__} is not supported; pass a path to the fit JSON, "
        "its dict, or a fit result with .to_json_dict()"
    )


def _number(where: str, value, *, allow_none: bool = False) -> float | None:
    return finite_number(f"fit JSON: {where}", value, allow_none=allow_none)


def _estimate(section: dict, name: str, group: str) -> Estimate | None:
    entry = section.get(name)
    if entry is None:
        return None
    if not isinstance(entry, dict) or "value" not in entry:
        raise InputError(f"fit JSON: {group}.{name} must be an object with a 'value'")
    where = f"{group}.{name}"
    value = _number(f"{where}.value", entry["value"])
    stderr = _number(f"{where}.stderr", entry.get("stderr"), allow_none=True)
    ci = entry.get("ci95")
    if ci is not None:
        if not isinstance(ci, (list, tuple)) or len(ci) != 2:
            raise InputError(f"fit JSON: {where}.ci95 = {shown(ci)} must be [low, high] or null")
        lo = _number(f"{where}.ci95[0]", ci[0], allow_none=True)
        hi = _number(f"{where}.ci95[1]", ci[1], allow_none=True)
        ci = None if lo is None or hi is None else (min(lo, hi), max(lo, hi))
    return Estimate(value, stderr, ci)


def _identifiable(fit: dict, name: str, est: Estimate | None) -> bool:
    flags = fit.get("identifiable") or {}
    if name in flags:
        return bool(flags[name])
    return est is not None and est.stderr is not None


# -- propagation ----------------------------------------------------------------------


def _scale(est: Estimate | None, factor: float) -> Estimate | None:
    if est is None:
        return None
    ci = None if est.ci95 is None else (est.ci95[0] * factor, est.ci95[1] * factor)
    return Estimate(est.value * factor, None if est.stderr is None else est.stderr * abs(factor), ci)


def _monotone(est: Estimate | None, f, df) -> Estimate | None:
    """f(X) for a monotone f: the interval's image (exact) and a delta-method stderr."""
    if est is None:
        return None
    stderr = None if est.stderr is None else abs(df(est.value)) * est.stderr
    ci = None
    if est.ci95 is not None:
        a, b = f(est.ci95[0]), f(est.ci95[1])
        ci = (min(a, b), max(a, b))
    return Estimate(f(est.value), stderr, ci)


def _clip_e(e: float) -> float:
    return min(max(e, 1e-300), 1.0)


@dataclass(frozen=True)
class MujocoContact:
    """MuJoCo contact settings for identified contact parameters (see `mujoco_contact`).

    Every `Estimate` carries the fit's uncertainty: a value, a standard error
    (delta method) and a 95% interval (the exact image of the fit's interval of
    the one fitted quantity each setting depends on monotonically; `None` where the
    fit gives none).

    **Fields:**

    - `mode`: `"direct"` or `"standard"`, the `solref` format of `solref`.
    - `solref`: the two `solref` numbers, or `None` when κ is not identifiable.
    - `solimp`: the five `solimp` numbers (constant impedance d_0 = d_max).
    - `mass`: the effective contact mass m the settings assume, kg.
    - `fit_mass`: the mass the fit used (from the fit JSON), kg, or `None`.
    - `kappa`, `k_r`: the fit's κ (N/m) and k_r (N·s/m), `None` if unusable.
    - `stiffness`, `damping`: direct format, κ/m (1/s²) and k_r/m (1/s).
    - `timeconst`, `dampratio`: standard format, 2m/k_r (s) and ζ = k_r/(2√(κm)).
    - `restitution`, `contact_time`: the Kelvin–Voigt e and t_c (s) at mass m
      that the settings reproduce (the fit's own values when m is the fit's mass).
    - `mujoco_restitution`, `mujoco_contact_time`: what MuJoCo should measure
      for an impact without gravity, its force being unable to pull
      (`nonadhesive_rebound`); `None` where not computable.
    - `identifiable`: whether the fit identifies κ (otherwise only e-information).
    - `match`: `"law"` (κ/m, k_r/m) or `"rebound"` (settings that make MuJoCo's
      non-adhesive contact reproduce e and t_c).
    - `notes`: warnings and remarks, one sentence each.
    - `source`: the fit file's path, or `None`.
    """

    mode: str
    solref: tuple[float, float] | None
    solimp: tuple[float, float, float, float, float]
    mass: float
    fit_mass: float | None
    kappa: Estimate | None
    k_r: Estimate | None
    stiffness: Estimate | None
    damping: Estimate | None
    timeconst: Estimate | None
    dampratio: Estimate
    restitution: Estimate
    contact_time: Estimate | None
    mujoco_restitution: float | None
    mujoco_contact_time: float | None
    identifiable: bool
    notes: tuple[str, ...] = ()
    match: str = "law"
    source: str | None = None
    meta: tuple[tuple[str, str], ...] = ()

    @property
    def solref_ci95(self) -> tuple[tuple[float, float] | None, tuple[float, float] | None] | None:
        """95% intervals of the two `solref` numbers, in `solref`'s signs and order."""
        if self.solref is None:
            return None
        if self.mode == "standard":
            return (_ci(self.timeconst), _ci(self.dampratio))
        flip = lambda est: None if _ci(est) is None else (-est.ci95[1], -est.ci95[0])  # noqa: E731
        return (flip(self.stiffness), flip(self.damping))

    def attributes(self) -> dict[str, str]:
        """The geom attributes, as strings: `solref`, `solimp` and `priority`.

        `priority="1"` makes MuJoCo use this geom's `solref` and `solimp` for its
        contacts instead of mixing them with the other geom's (MuJoCo averages
        standard-format `solref`s and `solimp`s of geoms of equal priority). Empty
        when κ is not identifiable.
        """
        if self.solref is None:
            return {}
        return {
            "solref": " ".join(_g(v, 8) for v in self.solref),
            "solimp": " ".join(_g(v) for v in self.solimp),
            "priority": "1",
        }

    def mjcf(self) -> str:
        """An MJCF snippet: an XML comment on units and assumptions, then the geom attributes.

        Paste the last line into the ball's `<geom .../>`. Without an identified κ
        the snippet is the comment alone, with the e-only information.
        """
        lines = [f"jaxunilat export mujoco{'' if self.source is None else ': ' + self.source}"]
        lines += [f"{k}: {v}" for k, v in self.meta]
        lines.append(f"effective contact mass m = {_g(self.mass)} kg ({self._mass_origin()})")
        lines.append(
            "assumes the ball's mass is the contact's effective mass (ball on a fixed or much heavier "
            "body); between two moving bodies pass the reduced mass m1*m2/(m1+m2) as the mass"
        )
        if self.kappa is not None and self.identifiable:
            lines.append(f"fit: kappa = {_est(self.kappa)} N/m, k_r = {_est(self.k_r)} N*s/m")
        lines.append(f"restitution e = {_est(self.restitution)} (Kelvin-Voigt)")
        if self.contact_time is not None and self.identifiable:
            lines.append(f"contact time t_c = {_est(self.contact_time, 1e3)} ms (Kelvin-Voigt)")
        if self.solref is None:
            lines.append(
                f"no solref: kappa is not identifiable from this fit, only e; standard format: "
                f"dampratio = {_est(self.dampratio)} (a function of e alone"
                f"{', for a contact that cannot pull' if self.match == 'rebound' else ''}), "
                "timeconst (2m/k_r) needs a contact time t_c from elsewhere; "
                "direct format: damping = 2*dampratio*sqrt(stiffness)"
            )
        elif self.mode == "direct":
            what = (
                ("kappa/m", "k_r/m")
                if self.match == "law"
                else ("(omega' t_c)^2/t_c^2", "2 zeta' omega' (matched to e and t_c)")
            )
            lines.append(
                f"solref direct format (-stiffness -damping) in acceleration units: stiffness = {what[0]} "
                f"= {_est(self.stiffness)} 1/s^2, damping = {what[1]} = {_est(self.damping)} 1/s "
                "(NOT kappa and k_r themselves)"
            )
        else:
            what = (
                ("2m/k_r", "k_r/(2 sqrt(kappa m))")
                if self.match == "law"
                else ("1/(zeta' omega')", "zeta' (matched to e and t_c)")
            )
            lines.append(
                f"solref standard format (timeconst dampratio): timeconst = {what[0]} = "
                f"{_est(self.timeconst)} s, dampratio = {what[1]} = {_est(self.dampratio)}; "
                "MuJoCo raises timeconst to 2*timestep unless refsafe is disabled"
            )
        if self.solref is not None:
            lines.append(
                f"solimp: constant impedance d0 = dmax = {_g(self.solimp[0])} (d_max cancels from the "
                "mapping; width, midpoint and power are unused)"
            )
            lines.append(
                "priority=1: this geom's solref/solimp are used for its contacts, not mixed with the other geom's"
            )
            if self.mujoco_restitution is not None:
                tc = (
                    ""
                    if self.mujoco_contact_time is None
                    else f", t_c = {self.mujoco_contact_time * 1e3:.5g} ms"
                )
                if self.match == "law":
                    lines.append(
                        f"MuJoCo's contact force cannot pull, so expect e = {self.mujoco_restitution:.5g}{tc} "
                        "(without gravity)"
                    )
                else:
                    lines.append(
                        f"MuJoCo's contact cannot pull; these settings make it rebound with "
                        f"e = {self.mujoco_restitution:.5g}{tc} (without gravity)"
                    )
            if self.contact_time is not None:
                lines.append(
                    f"resolve the contact: timestep <= t_c/100 = {_g(self.contact_time.value / 100, 2)} s "
                    'with integrator="RK4"; with the default pyramidal cone the normal response matches '
                    'only for sliding friction 1; otherwise use cone="elliptic" or condim="1"'
                )
        lines += [f"warning: {note}" for note in self.notes]
        body = "\n".join("     " + _xml_safe(line) for line in lines)
        snippet = "<!--" + body[4:] + " -->"
        attrs = self.attributes()
        if attrs:
            snippet += "\n" + " ".join(f'{k}="{v}"' for k, v in attrs.items())
        return snippet

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field (estimates as {value, stderr, ci95})."""
        out: dict[str, Any] = {}
        for name in self.__dataclass_fields__:
            v = getattr(self, name)
            if isinstance(v, Estimate):
                v = {"value": v.value, "stderr": v.stderr, "ci95": None if v.ci95 is None else list(v.ci95)}
            elif isinstance(v, tuple) and name != "meta":
                v = list(v)
            elif name == "meta":
                v = dict(v)
            out[name] = v
        out["attributes"] = self.attributes()
        return out

    def _mass_origin(self) -> str:
        if self.fit_mass is None:
            return "given; the fit JSON has no mass"
        if math.isclose(self.mass, self.fit_mass, rel_tol=1e-12):
            return "the fit's"
        return f"given; the fit used {_g(self.fit_mass)} kg"

    def __str__(self) -> str:
        return self.mjcf()


def _ci(est: Estimate | None):
    return None if est is None else est.ci95


def _g(x: float, digits: int = 6) -> str:
    return f"{x:.{digits}g}"


def _est(est: Estimate | None, factor: float = 1.0) -> str:
    if est is None:
        return "n/a"
    text = _g(est.value * factor)
    if est.ci95 is not None:
        lo, hi = est.ci95[0] * factor, est.ci95[1] * factor
        # Enough digits to tell the ends apart: two beyond the interval's width.
        scale = max(abs(lo), abs(hi), 1e-300)
        width = abs(hi - lo)
        digits = 4 if width == 0 else min(12, max(4, math.ceil(math.log10(scale / width)) + 2))
        text += f" [95% CI {_g(lo, digits)}, {_g(hi, digits)}]"
    elif est.stderr is None:
        text += " (no CI)"
    return text


def _xml_safe(text: str) -> str:
    """An XML comment may not contain '--' (nor end with '-'), nor control characters (a
    file name's newline or escape bytes: shown escaped, `printable`)."""
    text = printable(text)
    while "--" in text:
        text = text.replace("--", "-")
    return text


# -- the entry point --------------------------------------------------------------------


def mujoco_contact(
    fit_or_path,
    *,
    mass: float | None = None,
    mode: str = "direct",
    match: str = "law",
    impedance: float = DEFAULT_IMPEDANCE,
) -> MujocoContact:
    """MuJoCo `solref`/`solimp` for a fit's κ and k_r, with the fit's uncertainty.

    Direct mode: `solref = (−κ/m, −k_r/m)`, MuJoCo's direct format in acceleration
    units. Standard mode: `solref = (2m/k_r, ζ)`, the (timeconst, dampratio) pair
    that gives the same stiffness and damping under MuJoCo's documented mapping
    (d_max cancels; see the module docstring). `solimp = (d, d, 0.001, 0.5, 2)`,
    a constant impedance d. MuJoCo then reproduces the fit's restitution e and
    contact time t_c, except that its contact force cannot pull (see
    `nonadhesive_rebound`).

    A fit that does not identify κ gives a warning and the e-only information
    (`solref = None`, `dampratio` and `restitution` set), not invented numbers.

    **Arguments:**

    - `fit_or_path`: the path of a fit JSON (`jaxunilat identify --json`), its dict,
      or a fit result with `.to_json_dict()`.
    - `mass`: the effective contact mass m, kg (> 0). Default: the fit's `mass`.
      A different mass keeps the fit's κ and k_r (N/m, N·s/m), so e and t_c
      change: use it for the reduced mass m₁m₂/(m₁ + m₂) of two moving bodies.
    - `mode`: `"direct"` or `"standard"`.
    - `match`: `"law"` (default): MuJoCo gets the fitted force law, stiffness κ/m
      and damping k_r/m, and its rebound is slightly more elastic than the fit's
      (its force cannot pull). `"rebound"`: the stiffness and damping are chosen
      so that MuJoCo's non-adhesive contact reproduces the fit's e and t_c
      (`nonadhesive_rebound` inverted); they then differ from κ/m and k_r/m.
    - `impedance`: d_0 = d_max of `solimp`, in [0.0001, 0.9999]. The nearer 1, the
      closer MuJoCo's contact is to a pure spring–damper (a fraction 1 − d of the
      other forces, e.g. gravity, still acts during contact).

    **Returns:** a `MujocoContact`; `.mjcf()` is the snippet, `.attributes()` the
    geom attributes, `.to_dict()` a JSON-ready dict.

    **Raises:** `ValueError` for a missing or malformed fit file, a non-positive or
    missing mass, an unknown mode, a fit that identifies neither κ nor e, or
    settings MuJoCo cannot express (k_r = 0 in standard mode; ζ ≥ 1).
    """
    check_choice("mode", mode, MODES)
    check_choice("match", match, MATCHES)
    check_range("impedance", impedance, lo=_MIN_IMP, hi=_MAX_IMP)
    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg", allow_none=True)
    fit = _read_fit(fit_or_path, mass)
    notes: list[str] = []
    if fit.raw.get("converged") is False:
        notes.append("the fit did not converge; check it before using these settings")
    e_fit = _fit_restitution(fit)
    zeta_fit, dampratio = _dampratio_at_mass(e_fit, fit)
    same_mass = math.isclose(fit.mass, fit.m_fit, rel_tol=1e-12)
    restitution = e_fit if same_mass else _restitution_at_mass(dampratio, fit, notes)
    common = dict(
        mode=mode,
        solimp=(float(impedance), float(impedance), 0.001, 0.5, 2.0),
        mass=fit.mass,
        fit_mass=fit.fit_mass,
        source=fit.source,
        meta=tuple((k, str(fit.raw[k])) for k in ("data", "scene", "observe") if fit.raw.get(k) is not None),
    )
    if not fit.kappa_ok:
        return _e_only_contact(dampratio, restitution, match, notes, common)

    settings = _law_settings(fit, e_fit, zeta_fit, dampratio, restitution, same_mass, notes)
    if match == "rebound":
        settings = _rebound_settings(settings, fit, notes)
    return MujocoContact(
        solref=_solref(mode, settings),
        kappa=fit.kappa,
        k_r=fit.k_r,
        identifiable=True,
        notes=tuple(notes),
        match=match,
        **settings._asdict(),
        **common,
    )


class _Fit(NamedTuple):
    """The fit JSON's numbers, validated: κ (N/m), k_r (N·s/m), e, t_c (s) and the masses (kg)."""

    raw: dict  # the fit JSON itself (flags, correlation, converged, meta)
    source: str | None  # the fit file's path
    kappa: Estimate | None
    k_r: Estimate | None
    restitution: Estimate | None  # the fit's derived e, if any
    contact_time: Estimate | None  # the fit's derived t_c (s), if any
    fit_mass: float | None  # the mass in the fit JSON, kg
    mass: float  # the effective contact mass of the settings, kg
    m_fit: float  # the mass the fit's e and t_c belong to, kg
    kappa_ok: bool  # whether κ is identifiable (and positive)


def _read_fit(fit_or_path, mass: float | None) -> _Fit:
    """Load the fit and check κ, k_r, e, t_c and the masses (kg); `mass` overrides the fit's."""
    fit, source = _load(fit_or_path)
    if not isinstance(fit, dict):
        raise InputError("fit JSON: the top level must be an object with 'parameters'")
    params = fit.get("parameters")
    if not isinstance(params, dict):
        raise InputError("fit JSON: 'parameters' (with 'kappa' and 'k_r') is missing")
    derived = fit.get("derived") or {}
    kappa = _estimate(params, "kappa", "parameters")
    k_r = _estimate(params, "k_r", "parameters")
    e_fit = _estimate(derived, "restitution", "derived")
    tc_fit = _estimate(derived, "contact_time", "derived")

    fit_mass = fit.get("mass")
    if fit_mass is not None:
        fit_mass = _number("mass", fit_mass)
        check_range("mass (in the fit JSON)", fit_mass, lo=0.0, lo_open=True, unit="kg")
        check_fit_value("fit JSON: mass", "mass", fit_mass)
    check_fit_value("mass", "mass", mass)
    for name, est in (("kappa", kappa), ("k_r", k_r), ("contact_time", tc_fit)):
        group = "derived" if name == "contact_time" else "parameters"
        if est is not None and (name != "kappa" or est.value > 0) and (name != "k_r" or est.value >= 0):
            check_fit_value(f"fit JSON: {group}.{name}.value", name, est.value)
    if mass is None:
        if fit_mass is None:
            raise InputError("the fit JSON has no 'mass'; pass the ball's mass in kg (mass=..., or --mass M)")
        mass = fit_mass
    mass = float(mass)
    m_fit = mass if fit_mass is None else fit_mass

    kappa_ok = _identifiable(fit, "kappa", kappa) and kappa is not None and kappa.value > 0
    if kappa is not None and kappa.value <= 0:
        raise InputError(f"fit JSON: parameters.kappa.value = {kappa.value:g} N/m must be > 0")
    if k_r is not None and k_r.value < 0:
        raise InputError(f"fit JSON: parameters.k_r.value = {k_r.value:g} N*s/m must be >= 0")
    if kappa_ok and k_r is None:
        raise InputError("fit JSON: parameters.k_r is missing")
    return _Fit(fit, source, kappa, k_r, e_fit, tc_fit, fit_mass, mass, m_fit, kappa_ok)


def _fit_restitution(fit: _Fit) -> Estimate:
    """The restitution e at the fit's mass: the fit's own, or from κ and k_r; checked to be in (0, 1]."""
    e_fit = fit.restitution
    if e_fit is None and fit.kappa is not None and fit.k_r is not None:
        zeta = _zeta_delta(fit.kappa, fit.k_r, fit.raw.get("correlation"), fit.m_fit)
        if zeta.value < 1:
            e_fit = _monotone(zeta, _e_from_zeta, _de_dzeta)
    e_ok = e_fit is not None and 0 < e_fit.value <= 1 and _identifiable(fit.raw, "restitution", e_fit)
    if not fit.kappa_ok and not e_ok:
        raise InputError(
            "the fit identifies neither kappa nor the restitution e; there is nothing to export "
            "(fit more informative data: impact times or a position trace)"
        )
    if e_fit is None or not 0 < e_fit.value <= 1:
        raise InputError("fit JSON: the restitution e must be in (0, 1]")
    return e_fit


def _dampratio_at_mass(e_fit: Estimate, fit: _Fit) -> tuple[Estimate, Estimate]:
    """ζ at the fit's mass from e (monotone), and ζ scaled to the effective mass.

    ζ = k_r/(2√(κm)) ∝ m^(-1/2) at fixed κ and k_r. Raises for ζ ≥ 1 (overdamped).
    """
    zeta_fit = _monotone(e_fit, lambda e: _zeta_from_e(_clip_e(e)), lambda e: _dzeta_de(_clip_e(e)))
    dampratio = _scale(zeta_fit, math.sqrt(fit.m_fit / fit.mass))
    if dampratio.value >= 1:
        raise InputError(
            f"damping ratio zeta = {dampratio.value:.3g} >= 1 at mass {fit.mass:g} kg: the contact is "
            "overdamped (no rebound); MuJoCo's settings would not reproduce a restitution"
        )
    return zeta_fit, dampratio


def _restitution_at_mass(dampratio: Estimate, fit: _Fit, notes: list[str]) -> Estimate:
    """e at an effective mass other than the fit's (same κ and k_r), with a note saying so."""
    notes.append(
        f"mass {fit.mass:g} kg differs from the fit's {fit.m_fit:g} kg: the settings keep the fitted kappa and "
        "k_r, so e and t_c are those of the new mass, not the fitted ones"
    )
    return _monotone(dampratio, _e_from_zeta, _de_dzeta)


def _e_only_contact(
    dampratio: Estimate, restitution: Estimate, match: str, notes: list[str], common: dict
) -> MujocoContact:
    """The result when κ is not identifiable: no `solref`, only e and the damping ratio it fixes."""
    e_mj = nonadhesive_rebound(dampratio.value)[0] if dampratio.value < 1 / math.sqrt(2) else None
    notes.insert(
        0,
        "kappa is not identifiable from this fit: no solref is exported, only the restitution and "
        "the damping ratio it fixes; a contact time (impact times or a position trace) would identify kappa",
    )
    if match == "rebound":
        dampratio = _rebound_dampratio(restitution)
    return MujocoContact(
        solref=None,
        kappa=None,
        k_r=None,
        stiffness=None,
        damping=None,
        timeconst=None,
        dampratio=dampratio,
        restitution=restitution,
        contact_time=None,
        mujoco_restitution=e_mj,
        mujoco_contact_time=None,
        identifiable=False,
        notes=tuple(notes),
        match=match,
        **common,
    )


class _Settings(NamedTuple):
    """MuJoCo settings for an identified κ, and the rebound they give (see `MujocoContact`)."""

    stiffness: Estimate  # direct format, 1/s²
    damping: Estimate  # direct format, 1/s
    timeconst: Estimate | None  # standard format, s (None for k_r = 0)
    dampratio: Estimate  # standard format, ζ
    restitution: Estimate  # Kelvin–Voigt e at the effective mass
    contact_time: Estimate | None  # Kelvin–Voigt t_c at the effective mass, s
    mujoco_restitution: float | None  # MuJoCo's non-adhesive e
    mujoco_contact_time: float | None  # MuJoCo's non-adhesive t_c, s


def _law_settings(
    fit: _Fit,
    e_fit: Estimate,
    zeta_fit: Estimate,
    dampratio: Estimate,
    restitution: Estimate,
    same_mass: bool,
    notes: list[str],
) -> _Settings:
    """Settings from κ and k_r (`match="law"`): stiffness κ/m, damping k_r/m, timeconst 2m/k_r.

    ζ's interval comes from e's (a function of e alone) unless e disagrees with κ, k_r
    and the mass; a note says so and every number then follows κ and k_r.
    """
    kappa, k_r, mass, m_fit = fit.kappa, fit.k_r, fit.mass, fit.m_fit
    zeta_direct = k_r.value / (2.0 * math.sqrt(kappa.value * mass))
    if not math.isclose(zeta_direct, dampratio.value, rel_tol=1e-3, abs_tol=1e-9):
        notes.append(
            f"the fit's restitution e = {e_fit.value:.6g} does not match kappa, k_r and the mass "
            f"{m_fit:g} kg (which give zeta = {zeta_direct * math.sqrt(mass / m_fit):.6g}, "
            f"not {zeta_fit.value:.6g}); check the mass"
        )
        # Keep every number consistent with the exported κ and k_r.
        dampratio = _zeta_delta(kappa, k_r, fit.raw.get("correlation"), mass)
        restitution = _monotone(dampratio, _e_from_zeta, _de_dzeta)
        same_mass = False  # the fit's e and t_c do not describe these κ and k_r
    dampratio = dampratio._replace(value=zeta_direct)
    e_mj, wt = nonadhesive_rebound(zeta_direct) if zeta_direct < 1 / math.sqrt(2) else (None, None)
    timeconst = None
    if k_r.value > 0:
        timeconst = _monotone(
            k_r, lambda c: 2.0 * mass / c if c > 0 else math.inf, lambda c: -2.0 * mass / c**2
        )
    if same_mass and fit.contact_time is not None:
        contact_time = fit.contact_time
    else:
        contact_time = _contact_time_delta(kappa, k_r, fit.raw.get("correlation"), mass)
    return _Settings(
        stiffness=_scale(kappa, 1.0 / mass),
        damping=_scale(k_r, 1.0 / mass),
        timeconst=timeconst,
        dampratio=dampratio,
        restitution=restitution,
        contact_time=contact_time,
        mujoco_restitution=e_mj,
        mujoco_contact_time=None if e_mj is None else wt * math.sqrt(mass / kappa.value),
    )


def _rebound_settings(law: _Settings, fit: _Fit, notes: list[str]) -> _Settings:
    """`match="rebound"`: settings whose non-adhesive contact rebounds with the law's e and t_c (s)."""
    if law.contact_time is None:
        raise InputError("match='rebound' needs the contact time t_c, which these parameters do not give")
    stiffness, damping, timeconst, dampratio = _match_rebound(law.restitution, law.contact_time)
    kappa, k_r, mass = fit.kappa, fit.k_r, fit.mass
    notes.append(
        "match='rebound': the stiffness and damping are chosen so that MuJoCo's contact, which cannot "
        f"pull, reproduces the fitted e and t_c; they are {stiffness.value * mass / kappa.value:.6g} and "
        f"{damping.value * mass / k_r.value if k_r.value > 0 else math.inf:.6g} times kappa/m and k_r/m"
    )
    return law._replace(
        stiffness=stiffness,
        damping=damping,
        timeconst=timeconst,
        dampratio=dampratio,
        mujoco_restitution=law.restitution.value,
        mujoco_contact_time=law.contact_time.value,
    )


def _solref(mode: str, settings: _Settings) -> tuple[float, float]:
    """The two `solref` numbers: (−stiffness, −damping) in 1/s², 1/s, or (timeconst (s), dampratio)."""
    if mode == "direct":
        return (-settings.stiffness.value, -settings.damping.value)
    if settings.timeconst is None:
        raise InputError(
            "k_r = 0: the standard format cannot express an undamped contact (timeconst = 2m/k_r is "
            "infinite); use mode='direct' (--mode direct)"
        )
    return (settings.timeconst.value, settings.dampratio.value)


def _zeta_for_rebound(e: float) -> float:
    """The damping ratio whose non-adhesive rebound (`nonadhesive_rebound`) has restitution e."""
    top = 1.0 / math.sqrt(2.0) * (1.0 - 1e-12)
    e_min = nonadhesive_rebound(top)[0]
    if e < e_min:
        raise InputError(
            f"e = {e:.4g}: a contact whose force cannot pull (MuJoCo's) gives no restitution below "
            f"{e_min:.4f} with a linear spring-damper; use match='law'"
        )
    lo, hi = 0.0, top
    if e >= 1.0:
        return 0.0
    for _ in range(80):  # e decreases monotonically with ζ
        mid = 0.5 * (lo + hi)
        if nonadhesive_rebound(mid)[0] > e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _rebound_dampratio(e: Estimate) -> Estimate:
    """ζ' with e_nonadhesive(ζ') = e: the interval is the image of e's, the stderr by the delta method."""
    zeta = _zeta_for_rebound(e.value)
    h = 1e-7
    lo_e, hi_e = max(e.value - h, 1e-300), min(e.value + h, 1.0)
    dz = (_zeta_for_rebound(hi_e) - _zeta_for_rebound(lo_e)) / (hi_e - lo_e)
    return Estimate(
        zeta,
        None if e.stderr is None else abs(dz) * e.stderr,
        None if e.ci95 is None else tuple(sorted(_zeta_for_rebound(min(v, 1.0)) for v in e.ci95)),
    )


def _match_rebound(e: Estimate, t_c: Estimate):
    """MuJoCo (stiffness, damping, timeconst, dampratio) whose non-adhesive rebound has e and t_c.

    ζ' solves e_nonadhesive(ζ') = e and ω' = (ω t_c)(ζ')/t_c; stiffness = ω'²,
    damping = 2ζ'ω', timeconst = 1/(ζ'ω'). ζ''s interval is the image of e's;
    the others are the image of t_c's at the fitted e (e is usually far better
    determined than t_c), with delta-method stderrs from t_c's.
    """
    dampratio = _rebound_dampratio(e)
    zeta = dampratio.value
    wt = nonadhesive_rebound(zeta)[1]

    def of_tc(f, power):
        stderr = None if t_c.stderr is None else abs(power) * f(t_c.value) * t_c.stderr / t_c.value
        ci = None if t_c.ci95 is None else tuple(sorted(f(v) for v in t_c.ci95))
        return Estimate(f(t_c.value), stderr, ci)

    stiffness = of_tc(lambda tc: (wt / tc) ** 2, 2)
    damping = of_tc(lambda tc: 2.0 * zeta * wt / tc, 1)
    timeconst = None if zeta == 0 else of_tc(lambda tc: tc / (zeta * wt), 1)
    return stiffness, damping, timeconst, dampratio


def _de_dzeta(zeta: float) -> float:
    if zeta >= 1:
        return 0.0
    s = math.sqrt(1.0 - zeta**2)
    return -math.pi / s**3 * _e_from_zeta(zeta)


def _correlation(correlation) -> float:
    try:
        rho = float(correlation[0][1])
    except (TypeError, IndexError, ValueError, KeyError):
        return 0.0
    return rho if math.isfinite(rho) else 0.0


def _zeta_delta(kappa: Estimate, k_r: Estimate, correlation, mass: float) -> Estimate:
    """ζ = k_r/(2√(κm)) with a delta-method stderr on log ζ = log k_r − ½ log κ − ½ log m."""
    zeta = k_r.value / (2.0 * math.sqrt(kappa.value * mass))
    if kappa.stderr is None or k_r.stderr is None or k_r.value <= 0:
        return Estimate(zeta)
    a, b = k_r.stderr / k_r.value, 0.5 * kappa.stderr / kappa.value
    sd = math.sqrt(max(a * a + b * b - 2.0 * _correlation(correlation) * a * b, 0.0))
    return Estimate(zeta, zeta * sd, (zeta * math.exp(-_Z95 * sd), zeta * math.exp(_Z95 * sd)))


def _contact_time_delta(kappa: Estimate, k_r: Estimate, correlation, mass: float) -> Estimate | None:
    """t_c = π/√(κ/m − (k_r/2m)²) at mass m, with a delta-method stderr and a normal 95% CI."""
    q = kappa.value / mass - (k_r.value / (2.0 * mass)) ** 2
    if q <= 0:
        return None
    tc = math.pi / math.sqrt(q)
    d_kappa = -0.5 * math.pi * q**-1.5 / mass
    d_kr = 0.5 * math.pi * q**-1.5 * k_r.value / (2.0 * mass**2)
    if kappa.stderr is None or k_r.stderr is None:
        return Estimate(tc)
    rho = _correlation(correlation)
    var = (d_kappa * kappa.stderr) ** 2 + (d_kr * k_r.stderr) ** 2
    var += 2.0 * rho * d_kappa * d_kr * kappa.stderr * k_r.stderr
    sd = math.sqrt(max(var, 0.0))
    return Estimate(tc, sd, (tc - _Z95 * sd, tc + _Z95 * sd))
