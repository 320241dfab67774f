"""`jaxunilat reproduce`: every figure and table of [K90], with the paper's claims checked.

All runs use the event mode (the exact model, every contact located). The ball runs
Table 1's examples from the paper's initial state; the coupling runs Table 2's
examples over the paper's 0–5 s run-up under both contact parameter sets (`stiff`,
the physical default, and `literal`, the paper's constants read in SI units) in
reading A (`paper`), and in reading B (`rotating`) unless `quick`.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable

import numpy as np

from .._internal._io import write_atomically

#: The figures `reproduce` writes (file name → what it shows).
FIGURES = {
    "fig04_ball_displacement_kr.png": "Fig. 4: ball displacement, examples 1-3 (k_r varies)",
    "fig05_ball_velocity_kr.png": "Fig. 5: ball velocity, examples 1-3 (k_r varies)",
    "fig06_ball_displacement_kappa.png": "Fig. 6: ball displacement, examples 4, 2, 5 (kappa varies)",
    "fig07_ball_velocity_kappa.png": "Fig. 7: ball velocity, examples 4, 2, 5 (kappa varies)",
    "fig08_ball_phase.png": "Fig. 8: ball phase diagram, example 2",
    "fig09_coupling_T_xi.png": "Fig. 9: joint impact force T_xi, Table 2 examples 1-6 (stiff)",
    "fig10_coupling_T_eta.png": "Fig. 10: joint impact force T_eta, Table 2 examples 1-6 (stiff)",
    "fig11_coupling_displacements.png": "Fig. 11: psi_xi and psi_eta, example 6 (stiff)",
    "fig12_coupling_phase_xi.png": "Fig. 12: phase diagram of psi_xi, example 6 (stiff)",
    "fig13_coupling_phase_eta.png": "Fig. 13: phase diagram of psi_eta, example 6 (stiff)",
    "fig14_coupling_trajectory.png": "Fig. 14: joint path on fixed axes, example 6 (stiff)",
    "fig09_10_coupling_forces_literal.png": "Figs 9-10 with the literal constants",
    "fig11_14_coupling_literal.png": "Figs 11-14 with the literal constants, example 6",
}
#: The summary `reproduce` writes next to the figures (Tables 1 and 2, the claims).
SUMMARY = "summary.md"

_BALL_RUN = dict(solver="event", rtol=1e-10, atol=1e-10, samples=2001, outputs=("x", "v"))
_COUPLING_OUTPUTS = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")
#: The coupling's run settings (shared with the tests, so one compilation serves both).
COUPLING_RUN = dict(
    solver="event",
    rtol=1e-9,
    atol=1e-12,
    samples=10001,
    outputs=_COUPLING_OUTPUTS,
    max_steps=32_768,
    max_events=4096,
)


@dataclasses.dataclass(frozen=True)
class Claim:
    """One claim of the paper: its statement, the outcome and the numbers behind it."""

    name: str
    passed: bool
    detail: str

    def line(self) -> str:
        return f"{'PASS' if self.passed else 'FAIL'}  {self.name}: {self.detail}"


@dataclasses.dataclass(frozen=True)
class Report:
    """What `reproduce` wrote and found: `figures` (paths), `summary` (path), `claims`."""

    figures: tuple[str, ...]
    summary: str
    claims: tuple[Claim, ...]


# -- runs ---------------------------------------------------------------------------


def _ball_runs(t1):
    from .._models._ball import Ball
    from .._solver._observe import contact_table
    from .._solver._simulate import simulate

    runs = {}
    for ex in range(1, 6):
        ball = Ball.table1(ex)
        sol = simulate(ball, ball.paper_initial_state(), t1, **_BALL_RUN)
        runs[ex] = dict(
            ball=ball,
            ts=np.asarray(sol.ts),
            x=np.asarray(sol.ys["x"]),
            v=np.asarray(sol.ys["v"]),
            table=contact_table(sol, ball),
        )
    return runs


def coupling_run(example, params="stiff", reading="paper", t1=5.0):
    """One Table 2 run (`example` 1–6, `params` "stiff" or "literal", `reading` "paper" or
    "rotating", over [0, `t1`] s) with the reproduction's settings.

    **Returns:** a dict: `model`; `ts` (s); `ys`, the outputs by name with the joint's
    position X, Y (m); `table`, the impact table; `peak`, `peak_xi`, `peak_eta`, the
    largest |T| (N); `median`, the median impact peak (N); `max_pen`, the deepest
    penetration in clearances δ.
    """
    from .._models._coupling import Coupling
    from .._solver._coupling_impacts import impact_table
    from .._solver._simulate import simulate

    model = Coupling.table2(example, params, reading, warn=False)
    sol = simulate(model, model.paper_initial_state(), t1, **COUPLING_RUN)
    ys = {k: np.asarray(v) for k, v in sol.ys.items()}
    ts = np.asarray(sol.ts)
    phi = np.asarray(model.phi(ts))
    arm = float(model.length)
    ys["X"] = arm * (ys["psi_eta"] * np.cos(phi) + ys["psi_xi"] * np.sin(phi))
    ys["Y"] = arm * (ys["psi_xi"] * np.cos(phi) - ys["psi_eta"] * np.sin(phi))
    table = impact_table(sol, model)
    peaks = table["peak_force"]
    return dict(
        model=model,
        ts=ts,
        ys=ys,
        table=table,
        peak=float(max(np.max(np.abs(ys["T_xi"])), np.max(np.abs(ys["T_eta"])))),
        peak_xi=float(np.max(np.abs(ys["T_xi"]))),
        peak_eta=float(np.max(np.abs(ys["T_eta"]))),
        median=float(np.median(peaks)) if len(peaks) else float("nan"),
        max_pen=float(
            np.max(np.maximum(np.abs(ys["psi_xi"]), np.abs(ys["psi_eta"])) - float(model.delta_xi))
            / float(model.delta_xi)
        ),
    )


# -- claims -------------------------------------------------------------------------


def _ball_energy(run):
    ball = run["ball"]
    m, g, kappa = float(ball.mass), float(ball.gravity), float(ball.kappa)
    x, v = run["x"], run["v"]
    pen = np.maximum(np.maximum(float(ball.lower) - x, x - float(ball.upper)), 0.0)
    return 0.5 * m * v**2 + m * g * (x - float(ball.lower)) + 0.5 * kappa * pen**2


def ball_claims(runs, t1) -> list[Claim]:
    """[K90 §5.1]: k_r lowers the amplitudes; κ changes amplitude and frequency; one upper contact."""
    claims = []
    checks = [t for t in (0.5, 1.0, 1.5, 2.0) if t <= t1]
    ts = runs[2]["ts"]
    idx = [int(np.argmin(np.abs(ts - t))) for t in checks]
    e = {ex: _ball_energy(runs[ex])[idx] for ex in (1, 2, 3)}
    ok = all(e[1][i] > e[2][i] > e[3][i] for i in range(len(idx)))
    detail = "; ".join(
        f"E({t:g} s) = {e[1][i]:.4g} > {e[2][i]:.4g} > {e[3][i]:.4g} J" for i, t in enumerate(checks)
    )
    claims.append(
        Claim("ball: k_r lowers the amplitudes (Figs 4-5, examples 1 > 2 > 3 in energy)", ok, detail)
    )

    dur = {}
    for ex in (4, 2, 5):
        tab = runs[ex]["table"]
        closed = ~np.isnan(tab["t_out"])
        dur[ex] = float(np.median(tab["t_out"][closed] - tab["t_in"][closed]))
    scaling = [dur[ex] * np.sqrt(float(runs[ex]["ball"].kappa)) for ex in (4, 2, 5)]
    freq_ok = dur[4] > dur[2] > dur[5] and (max(scaling) / min(scaling) - 1) < 0.05
    e_end = {ex: _ball_energy(runs[ex])[-1] for ex in (4, 2, 5)}
    amp_ok = min(abs(e_end[a] / e_end[b] - 1) for a, b in ((4, 2), (2, 5), (4, 5))) > 0.01
    claims.append(
        Claim(
            "ball: kappa changes amplitude and frequency (Figs 6-7, examples 4, 2, 5)",
            freq_ok and amp_ok,
            f"contact time {1e3 * dur[4]:.3f} / {1e3 * dur[2]:.3f} / {1e3 * dur[5]:.3f} ms "
            f"(~ kappa^-1/2 within {100 * (max(scaling) / min(scaling) - 1):.2f} %); "
            f"energy at {t1:g} s {e_end[4]:.4g} / {e_end[2]:.4g} / {e_end[5]:.4g} J",
        )
    )

    tab = runs[2]["table"]
    upper_t = tab["t_in"][tab["wall"] == "upper"]
    second = float(upper_t[1]) if len(upper_t) > 1 else float("nan")
    for window in (0.4, t1):
        n_up = int(np.sum(upper_t <= window))
        claims.append(
            Claim(
                f"ball: only one contact with the upper racket (Fig. 8, example 2), window [0, {window:g}] s",
                n_up == 1,
                f"{n_up} upper contact(s) by {window:g} s; the second is at {second:.4f} s, so the claim holds "
                f"only for windows shorter than that",
            )
        )
    return claims


#: A trend "rises" when each step up is at least this factor (a 0.01 % rise is not a trend).
MARGIN = 1.05


def _rises(*values) -> bool:
    return all(a >= MARGIN * b for a, b in zip(values[:-1], values[1:], strict=True))


def coupling_claims(runs, params, reading) -> list[Claim]:
    """[K90 §5.2]: impact forces rise with clearance, |α| and speed (each step ≥ `MARGIN`×)."""
    p = {ex: runs[ex]["peak"] for ex in runs}
    med = {ex: runs[ex]["median"] for ex in runs}
    n_imp = {ex: len(runs[ex]["table"]["t_in"]) for ex in runs}
    tag = f"{params}, reading {reading}"
    claims = [
        Claim(
            f"coupling ({tag}): impact forces rise with clearance (examples 1 > 2 > 3)",
            _rises(p[1], p[2], p[3]),
            f"peak kappa*D {p[1]:.4g} / {p[2]:.4g} / {p[3]:.4g} N (ratios {p[1] / p[2]:.3g}, {p[2] / p[3]:.3g})",
        ),
        Claim(
            f"coupling ({tag}): impact forces rise with |alpha| (examples 2 > 4 > 5)",
            _rises(p[2], p[4], p[5]),
            f"peak kappa*D {p[2]:.4g} / {p[4]:.4g} / {p[5]:.4g} N (ratios {p[2] / p[4]:.3g}, {p[4] / p[5]:.3g})",
        ),
    ]
    if min(n_imp[4], n_imp[6]) >= 3:
        claims.append(
            Claim(
                f"coupling ({tag}): impact forces rise with speed (example 4 > 6)",
                _rises(med[4], med[6]),
                f"median per-impact peak {med[4]:.4g} / {med[6]:.4g} N ({n_imp[4]} / {n_imp[6]} impacts); "
                f"single highest peak {p[4]:.4g} / {p[6]:.4g} N",
            )
        )
    else:
        claims.append(
            Claim(
                f"coupling ({tag}): impact forces rise with speed (example 4 > 6)",
                _rises(p[4], p[6]),
                f"peak kappa*D {p[4]:.4g} / {p[6]:.4g} N (too few separate impacts, "
                f"{n_imp[4]} / {n_imp[6]}, for a median)",
            )
        )
    return claims


# -- figures and summary --------------------------------------------------------------


def _write_figures(out, ball, coupling, literal, log) -> list[str]:
    from ..plot._ball import save_figure
    from ..plot._coupling import line_figure, plot_coupling, plot_impact_forces

    written = []

    def save(fig, name):
        path = os.path.join(out, name)
        save_figure(fig, path)
        written.append(path)
        log(f"wrote {path}")

    walls = (-0.4, 0.4)
    for name, exs, what in (
        ("fig04_ball_displacement_kr.png", (1, 2, 3), "x"),
        ("fig05_ball_velocity_kr.png", (1, 2, 3), "v"),
        ("fig06_ball_displacement_kappa.png", (4, 2, 5), "x"),
        ("fig07_ball_velocity_kappa.png", (4, 2, 5), "v"),
    ):
        curves = [
            (
                f"{ex}: kappa = {float(ball[ex]['ball'].kappa):g} N/m, k_r = {float(ball[ex]['ball'].k_r):g} N*s/m",
                ball[ex]["ts"],
                ball[ex][what],
            )
            for ex in exs
        ]
        ylabel = "displacement x [m]" if what == "x" else "velocity v [m/s]"
        save(
            line_figure(
                curves,
                xlabel="time t [s]",
                ylabel=ylabel,
                title=FIGURES[name],
                walls=walls if what == "x" else (),
            ),
            name,
        )
    b2 = ball[2]
    fig = line_figure(
        [("example 2", b2["x"], b2["v"])],
        xlabel="displacement x [m]",
        ylabel="velocity v [m/s]",
        title=FIGURES["fig08_ball_phase.png"],
    )
    for w in walls:
        fig.axes[0].axvline(w, color="0.35", linestyle="--", linewidth=0.9)
    save(fig, "fig08_ball_phase.png")

    for name, key in (("fig09_coupling_T_xi.png", "T_xi"), ("fig10_coupling_T_eta.png", "T_eta")):
        curves = [(f"example {ex}", r["ts"], 1e-3 * r["ys"][key]) for ex, r in coupling.items()]
        save(
            line_figure(curves, xlabel="time t [s]", ylabel=f"{key} = kappa*D [kN]", title=FIGURES[name]),
            name,
        )
    r6 = coupling[6]
    ys, ts, delta = r6["ys"], r6["ts"], 1e3 * float(r6["model"].delta_xi)
    save(
        line_figure(
            [("psi_xi", ts, 1e3 * ys["psi_xi"], "-"), ("psi_eta", ts, 1e3 * ys["psi_eta"], "--")],
            xlabel="time t [s]",
            ylabel="rotation [mrad]",
            title=FIGURES["fig11_coupling_displacements.png"],
            walls=(-delta, delta),
        ),
        "fig11_coupling_displacements.png",
    )
    for name, q in (("fig12_coupling_phase_xi.png", "xi"), ("fig13_coupling_phase_eta.png", "eta")):
        fig = line_figure(
            [("", 1e3 * ys[f"psi_{q}"], 1e3 * ys[f"dpsi_{q}"])],
            xlabel=f"psi_{q} [mrad]",
            ylabel=f"dpsi_{q}/dt [mrad/s]",
            title=FIGURES[name],
        )
        for w in (-delta, delta):
            fig.axes[0].axvline(w, color="0.35", linestyle="--", linewidth=0.9)
        save(fig, name)
    fig = line_figure(
        [("", 1e3 * ys["X"], 1e3 * ys["Y"])],
        xlabel="X [mm]",
        ylabel="Y [mm]",
        title=FIGURES["fig14_coupling_trajectory.png"],
        figsize=(6.5, 6.0),
    )
    fig.axes[0].set_aspect("equal", adjustable="datalim")
    save(fig, "fig14_coupling_trajectory.png")

    runs = [(f"example {ex}", r["ts"], r["ys"]["T_xi"], r["ys"]["T_eta"]) for ex, r in literal.items()]
    save(
        plot_impact_forces(runs, title="Figs 9-10, literal constants (kappa = 0.05 J, k_r = 0.02 J)"),
        "fig09_10_coupling_forces_literal.png",
    )
    l6 = literal[6]
    save(
        plot_coupling(
            l6["ts"],
            l6["ys"],
            delta=float(l6["model"].delta_xi),
            title="Figs 11-14, example 6, literal constants (penetration far beyond the clearance)",
        ),
        "fig11_14_coupling_literal.png",
    )
    return written


def _summary(ball, coupling_sets, claims, quick, t1_ball) -> str:
    lines = [
        "# jaxunilat reproduce: Kukla et al. (1990)",
        "",
        f"Mode: {'quick' if quick else 'full'}. Event mode (exact model, every contact located).",
        "",
        f"## Table 1: the ball (0-{t1_ball:g} s, paper's initial state)",
        "",
        "| example | kappa [N/m] | k_r [N*s/m] | contacts (lower/upper) | restitution per impact | "
        "contact time [ms] | peak force [N] | max penetration [mm] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for ex, r in ball.items():
        tab = r["table"]
        up = int(np.sum(tab["wall"] == "upper"))
        closed = ~np.isnan(tab["t_out"])
        rest = tab["restitution"][closed]
        fast = closed & (np.abs(tab["v_in"]) >= 1.0)
        dur = 1e3 * (tab["t_out"][fast] - tab["t_in"][fast])
        lines.append(
            f"| {ex} | {float(r['ball'].kappa):g} | {float(r['ball'].k_r):g} | {len(tab['t_in'])} "
            f"({len(tab['t_in']) - up}/{up}) | {_span(rest, '.4f')} | {_span(dur, '.3f')} | "
            f"{np.nanmax(tab['peak_force']):.4g} | {1e3 * np.nanmax(tab['max_penetration']):.3f} |"
        )
    lines += ["", "Restitution and contact time: impacts with |v_in| >= 1 m/s for the contact time.", ""]
    for (params, reading), runs in coupling_sets.items():
        lines += [
            f"## Table 2: the coupling, {params} constants, reading {reading} (0-5 s)",
            "",
            "| example | alpha | Delta [m] | b [1/s] | impacts | restitution per impact | peak T_xi [N] | "
            "peak T_eta [N] | median per-impact peak [N] | max penetration / delta |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for ex, r in runs.items():
            m = r["model"]
            rate = np.abs(r["table"]["rate_in"])
            hard = ~np.isnan(r["table"]["restitution"]) & (rate >= 0.1 * np.max(rate, initial=0.0))
            rest = r["table"]["restitution"][hard]
            lines.append(
                f"| {ex} | {float(m.alpha):g} | {float(m.clearance):g} | {float(m.b):g} | "
                f"{len(r['table']['t_in'])} | {_span(rest, '.3f')} | {r['peak_xi']:.4g} | {r['peak_eta']:.4g} | "
                f"{r['median']:.4g} | {r['max_pen']:.3g} |"
            )
        lines.append("")
    lines += [
        "Restitution: impacts arriving at >= 10 % of the run's fastest rate (slow touch-downs and",
        "rolling contacts have no meaningful ratio). Forces are the elastic parts kappa*D of Figs 9-10.",
        "The literal constants (kappa = 0.05 J_xi, k_r = 0.02 J_xi in SI) let the joint sink far beyond",
        "its clearance: they are not a physical model.",
        "",
        "## Claims of the paper",
        "",
        f"A coupling trend passes when each step rises by at least {100 * (MARGIN - 1):.0f} %.",
        "",
    ]
    lines += [f"- {c.line()}" for c in claims]
    lines.append("")
    return "\n".join(lines)


def _span(values, fmt) -> str:
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return "-"
    lo, hi = float(np.min(values)), float(np.max(values))
    return f"{lo:{fmt}}" if lo == hi else f"{lo:{fmt}}-{hi:{fmt}}"


def reproduce(out: str | os.PathLike, *, quick: bool = False, log: Callable[[str], None] = print) -> Report:
    """Regenerate the paper's figures and tables and check its claims.

    **Arguments:**

    - `out`: the output directory (created if missing).
    - `quick`: reading A only and a 2 s ball horizon (full: both readings).
    - `log`: where progress lines and the claims report go.

    **Returns:** a `Report` (figure paths, summary path, claims).
    """
    out = os.fspath(out)
    os.makedirs(out, exist_ok=True)
    t1_ball = 2.0
    ball = _ball_runs(t1_ball)
    claims = ball_claims(ball, t1_ball)
    readings = ("paper",) if quick else ("paper", "rotating")
    sets = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for reading in readings:
            for params in ("stiff", "literal"):
                runs = {ex: coupling_run(ex, params, reading) for ex in range(1, 7)}
                sets[(params, reading)] = runs
                claims += coupling_claims(runs, params, reading)
    figures = _write_figures(out, ball, sets[("stiff", "paper")], sets[("literal", "paper")], log)
    summary = os.path.join(out, SUMMARY)
    with write_atomically(summary) as f:
        f.write(_summary(ball, sets, claims, quick, t1_ball))
    log(f"wrote {summary}")
    log("claims of [K90]:")
    for c in claims:
        log(c.line())
    return Report(figures=tuple(figures), summary=summary, claims=tuple(claims))
