"""The ball of a recording: presets of common balls, and the quadratic drag of a sphere.

A data file's `mass` scales κ and k_r, and its `drag` (k = 1/terminal speed, s/m) bends
every flight; neither can be read from the onsets. An importer therefore needs the ball
stated: a preset (`BALLS`), or a mass with a diameter (or with the drag itself).

**The presets** (mass, diameter; a material's density where the ball has no standard size):

| name | mass | diameter | reference |
|---|---|---|---|
| `pingpong` | 2.7 g | 40 mm | ITTF Laws of Table Tennis 2.3 (2.03): 40 mm, 2.7 g |
| `tennis` | 57.7 g | 67.0 mm | ITF Rules of Tennis, Appendix I, types 1-2: 56.0-59.4 g, 6.54-6.86 cm (mid values) |
| `golf` | 45.93 g | 42.67 mm | USGA/R&A Equipment Rules, Part 4 (balls): at most 45.93 g, at least 42.67 mm (the limits) |
| `squash` | 24 g | 40 mm | World Squash ball specification: 24.0 ± 1.0 g, 40.0 ± 0.5 mm |
| `racquetball` | 39.7 g | 57.15 mm | USA Racquetball Rules 2.2: 2 1/4 in, about 1.4 oz |
| `basketball` | 608.5 g | 243.4 mm | FIBA Official Basketball Rules, equipment, size 7: 567-650 g, circumference 749-780 mm (mid values) |
| `baseball` | 145.3 g | 73.8 mm | MLB Official Baseball Rules 3.01: 5-5 1/4 oz, circumference 9-9 1/4 in (mid values) |
| `lacrosse` | 145.3 g | 63.7 mm | NCAA Lacrosse Rules (the ball): 5-5 1/4 oz, circumference 7 3/4-8 in (mid values) |
| `glass-marble` | 5.36 g | 16 mm | soda-lime glass, 2500 kg/m³ (EN 572-1); 16 mm, a common marble (no standard size) |
| `steel` | from `diameter` | required | structural steel, 7850 kg/m³ (EN 1991-1-1, Table A.4); no standard size |

**The drag.** The flight model's drag is ẍ = −g − g k² v|v| (`jaxunilat`'s closed-form
flight). For a sphere of diameter d and mass m the air's force ½ ρ C_d A v² (A = π d²/4)
equals m g k² v², so k = sqrt(ρ C_d A / (2 m g)), with

- ρ = `AIR_DENSITY` = 1.204 kg/m³: dry air at 20 °C and 101.325 kPa (ρ = p M / (R T),
  M = 0.0289644 kg/mol, the molar mass of dry air of the ISO 2533 standard atmosphere);
- C_d = `SPHERE_DRAG_COEFFICIENT` = 0.47: a smooth sphere below the drag crisis
  (10³ < Re < 2·10⁵; F. M. White, *Fluid Mechanics*, Table 7.3: 0.47 laminar; S. F. Hoerner,
  *Fluid-Dynamic Drag*, 1965). A drop test stays there: Re = v d / ν ≈ 3·10³ for a
  ping-pong ball at 1 m/s, 10⁵ for a basketball at 6 m/s. A felt-covered tennis ball drags
  more: C_d = 0.507 ± 0.024 in free flight (R. Cross and C. Lindsey, "Measurements of drag and
  lift on tennis balls in flight", *Sports Engineering*, 2014), 0.55-0.7 in wind tunnels
  (S. G. Goodwill, S. B. Chin and S. J. Haake, *J. Wind Eng. Ind. Aerodyn.* 92, 2004;
  R. Mehta, F. Alam and A. Subic, *Sports Technology* 1, 2008); its preset takes 0.55.

This gives k = 0.116 s/m for a ping-pong ball (terminal speed 8.6 m/s), 0.0454 s/m for a
tennis ball, 0.047 s/m for a basketball; `ball_spec` writes it to 3 significant digits (C_d
is known to no better). A stated drag (`drag`) replaces the computed one.
"""

from __future__ import annotations

import dataclasses
import math

from jaxunilat._internal import InputError

from ._format import DEFAULT_GRAVITY

#: Air density, kg/m³: dry air at 20 °C and 101.325 kPa, ρ = p M / (R T) = 1.204.
AIR_DENSITY = 1.204
#: Drag coefficient of a smooth sphere at subcritical Reynolds number (10³ < Re < 2·10⁵).
SPHERE_DRAG_COEFFICIENT = 0.47
#: The largest diameter accepted, m (a larger one is millimetres written as metres).
MAX_DIAMETER = 1.0


@dataclasses.dataclass(frozen=True)
class BallPreset:
    """A kind of ball: its mass (kg) and diameter (m), or for a solid ball of one material
    with no standard size, its density (kg/m³) and a diameter the user must give (None).

    - `drag_coefficient`: C_d of the quadratic drag, and `drag_source`, where it comes from.
    - `reference`: the rule or standard the size and mass come from.
    """

    name: str
    what: str
    reference: str
    mass: float | None = None
    diameter: float | None = None
    density: float | None = None
    drag_coefficient: float = SPHERE_DRAG_COEFFICIENT
    drag_source: str = "a smooth sphere, subcritical Re"


_OZ, _INCH = 28.349523125e-3, 25.4e-3  # kg, m (avoirdupois ounce, inch)

#: The presets, by name (`--ball NAME`); see the module docstring for the table.
BALLS: dict[str, BallPreset] = {
    b.name: b
    for b in (
        BallPreset("pingpong", "a 40 mm table-tennis ball", "ITTF Laws 2.3: 40 mm, 2.7 g", 2.7e-3, 0.040),
        BallPreset(
            "tennis",
            "a tennis ball",
            "ITF Rules of Tennis, Appendix I: 56.0-59.4 g, 6.54-6.86 cm; mid values",
            57.7e-3,
            0.0670,
            drag_coefficient=0.55,
            drag_source="felt: 0.51 in free flight (Cross & Lindsey 2014), 0.55-0.7 in wind tunnels",
        ),
        BallPreset(
            "golf",
            "a golf ball",
            "USGA/R&A Equipment Rules: at most 45.93 g, at least 42.67 mm",
            45.93e-3,
            0.04267,
        ),
        BallPreset("squash", "a squash ball", "World Squash: 24.0 +- 1.0 g, 40.0 +- 0.5 mm", 24.0e-3, 0.040),
        BallPreset(
            "racquetball",
            "a racquetball",
            "USA Racquetball Rules 2.2: 2 1/4 in, about 1.4 oz",
            1.4 * _OZ,
            2.25 * _INCH,
        ),
        BallPreset(
            "basketball",
            "a size 7 basketball",
            "FIBA size 7: 567-650 g, circumference 749-780 mm; mid values",
            608.5e-3,
            764.5e-3 / math.pi,
        ),
        BallPreset(
            "baseball",
            "a baseball",
            "MLB Official Baseball Rules 3.01: 5-5 1/4 oz, circumference 9-9 1/4 in; mid values",
            5.125 * _OZ,
            9.125 * _INCH / math.pi,
        ),
        BallPreset(
            "lacrosse",
            "a lacrosse ball",
            "NCAA Lacrosse Rules: 5-5 1/4 oz, circumference 7 3/4-8 in; mid values",
            5.125 * _OZ,
            7.875 * _INCH / math.pi,
        ),
        BallPreset(
            "glass-marble",
            "a 16 mm soda-lime glass marble",
            "soda-lime glass 2500 kg/m^3 (EN 572-1); 16 mm, a common size (none is standard)",
            diameter=0.016,
            density=2500.0,
        ),
        BallPreset(
            "steel",
            "a steel ball",
            "steel 7850 kg/m^3 (EN 1991-1-1, Table A.4); no standard size: give the diameter",
            density=7850.0,
        ),
    )
}


def sphere_drag(
    mass: float,
    diameter: float,
    *,
    drag_coefficient: float = SPHERE_DRAG_COEFFICIENT,
    air_density: float = AIR_DENSITY,
    gravity: float = DEFAULT_GRAVITY,
) -> float:
    """The quadratic drag k = 1/terminal speed, s/m, of a sphere of `mass` (kg) and
    `diameter` (m): ½ ρ C_d (π d²/4) v² = m g k² v², so k = sqrt(ρ C_d π d² / (8 m g))."""
    area = math.pi * diameter**2 / 4.0
    return math.sqrt(air_density * drag_coefficient * area / (2.0 * mass * gravity))


def solid_mass(density: float, diameter: float) -> float:
    """The mass, kg, of a solid sphere of `density` (kg/m³) and `diameter` (m)."""
    return density * math.pi * diameter**3 / 6.0


@dataclasses.dataclass(frozen=True)
class BallSpec:
    """The ball of an import: what the data set's `mass` and `drag` are, and why.

    - `mass` (kg), `drag` (s/m): the values written.
    - `ball`: the preset's name, or None (mass and drag stated).
    - `label`: the ball in a few words, for the data file's `source`.
    - `notes`: where the mass and the drag came from, one line each (`##` comments).
    """

    mass: float
    drag: float
    ball: str | None
    label: str
    notes: tuple[str, ...]


def preset_names(sep: str = "|") -> str:
    """The presets' names joined by `sep`."""
    return sep.join(BALLS)


def not_stated(*, cli: bool) -> str:
    """The sentence that asks for the ball: the presets and the flags (`cli`) or the keywords."""
    if cli:
        return (
            f"the ball is not stated: give --ball {preset_names()} (steel: with --diameter M) or --mass KG "
            "with --diameter M (or --drag S_PER_M)"
        )
    names = "|".join(repr(n) for n in BALLS)
    return (
        f"the ball is not stated: give ball={names} (steel: with diameter=M) or mass=KG with diameter=M "
        "(or drag=S_PER_M); ball='pingpong' is the 40 mm, 2.7 g ball these importers used to assume"
    )


def is_stated(*, ball=None, mass=None, diameter=None, drag=None) -> bool:
    """Whether these say the ball: a preset, or a mass with a diameter or a drag."""
    return ball is not None or (mass is not None and (diameter is not None or drag is not None))


def ball_spec(
    ball: str | None = None,
    *,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    cli: bool = False,
) -> BallSpec:
    """The mass and drag of a stated ball, with notes saying where each came from.

    `ball`: a preset's name (`BALLS`); `mass` (kg) and `diameter` (m) replace the preset's
    (a density preset needs `diameter`); `drag` (s/m) replaces the drag computed from them
    (`sphere_drag`, with `air_density`, kg/m³, default `AIR_DENSITY`). Without a preset,
    `mass` and one of `diameter` or `drag` are needed. An `InputError` says what is missing,
    in the command line's flags with `cli`.
    """
    from jaxunilat._internal import check_range

    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg", allow_none=True)
    check_range("diameter", diameter, lo=0.0, lo_open=True, unit="m", allow_none=True)
    if diameter is not None and diameter > MAX_DIAMETER:
        raise InputError(
            f"diameter = {diameter:g} m is out of range; valid range is (0, {MAX_DIAMETER:g}] m "
            "(millimetres written as metres?)"
        )
    check_range("drag", drag, lo=0.0, unit="s/m", allow_none=True)
    check_range("air density", air_density, lo=0.0, lo_open=True, unit="kg/m^3", allow_none=True)
    preset = _preset(ball)
    if not is_stated(ball=ball, mass=mass, diameter=diameter, drag=drag):
        raise InputError(_why_not(mass, diameter, drag, cli) + not_stated(cli=cli))
    d = diameter if diameter is not None else preset.diameter if preset else None
    if d is None and (drag is None or (mass is None and preset.mass is None)):
        ball_text, flag = (
            (f"--ball {preset.name}", "--diameter M") if cli else (f"ball={preset.name!r}", "diameter=M")
        )
        raise InputError(
            f"{ball_text} has no standard size: give {flag} (its mass follows from the density, "
            f"{preset.density:g} kg/m^3)"
        )
    notes: list[str] = []
    m = _mass(preset, mass, d, notes)
    rho = AIR_DENSITY if air_density is None else air_density
    if drag is None:
        k = _drag(preset, m, d, rho, notes)
    else:
        k = drag
        would = f" (the ball's diameter and mass give {_k(preset, m, d, rho):.3g})" if d is not None else ""
        notes.append(f"drag = {drag:g} s/m as stated{would}")
    stated = [n for n, v in (("mass", mass), ("diameter", diameter), ("drag", drag)) if v is not None]
    label = preset.name if preset else "as stated"
    if preset and stated:
        label += f" with {', '.join(stated)} stated"
    return BallSpec(mass=m, drag=k, ball=preset.name if preset else None, label=label, notes=tuple(notes))


def _preset(ball: str | None) -> BallPreset | None:
    if ball is None:
        return None
    key = str(ball).strip().lower().replace("_", "-").replace(" ", "-")
    if key not in BALLS:
        raise InputError(f"ball {ball!r} is not a preset; presets: {preset_names(', ')}")
    return BALLS[key]


def _why_not(mass, diameter, drag, cli: bool) -> str:
    """What of the ball was given, when it is not enough (a prefix of the refusal)."""
    flag = (lambda n: f"--{n}") if cli else (lambda n: f"{n}=")
    given = [flag(n) for n, v in (("mass", mass), ("diameter", diameter), ("drag", drag)) if v is not None]
    return f"{' and '.join(given)} alone: " if given else ""


def _mass(preset: BallPreset | None, mass, d, notes: list[str]) -> float:
    """The mass, kg: as stated, the preset's, or from the preset's density and `d`."""
    if preset is not None:
        notes.append(f"ball: {preset.name}, {preset.what} ({preset.reference})")
    if mass is not None:
        own = _own_mass(preset, d) if preset else None
        notes.append(f"mass = {mass:g} kg as stated" + (f" (the preset's: {own:.4g} kg)" if own else ""))
        return mass
    m = _own_mass(preset, d)
    if preset.mass is None:
        notes.append(f"mass = {m:g} kg: a solid sphere of {preset.density:g} kg/m^3, d = {d:g} m")
    else:
        notes.append(f"mass = {m:g} kg (ball {preset.name})")
    return m


def _own_mass(preset: BallPreset, d) -> float | None:
    if preset.mass is not None:
        return preset.mass
    return float(f"{solid_mass(preset.density, d):.4g}") if d is not None else None


def _k(preset: BallPreset | None, m: float, d: float, rho: float) -> float:
    """The drag computed for the ball, s/m, to 3 significant digits (C_d is known to no better)."""
    cd = preset.drag_coefficient if preset else SPHERE_DRAG_COEFFICIENT
    return float(f"{sphere_drag(m, d, drag_coefficient=cd, air_density=rho):.3g}")


def _drag(preset: BallPreset | None, m: float, d: float, rho: float, notes: list[str]) -> float:
    """The drag computed from the ball's mass `m` and diameter `d`, noted."""
    k = _k(preset, m, d, rho)
    cd, why = (
        (preset.drag_coefficient, preset.drag_source)
        if preset
        else (SPHERE_DRAG_COEFFICIENT, "a smooth sphere")
    )
    air = "dry air at 20 C, 101.325 kPa" if rho == AIR_DENSITY else "as stated"
    notes.append(
        f"drag = {k:g} s/m = sqrt(rho C_d pi d^2 / (8 m g)) with rho = {rho:g} kg/m^3 ({air}), C_d = {cd:g} "
        f"({why}), d = {d:.4g} m, m = {m:.4g} kg, g = {DEFAULT_GRAVITY:g} m/s^2 (a stated drag replaces it)"
    )
    return k
