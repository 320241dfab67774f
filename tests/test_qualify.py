"""`qualify` and `jaxunilat qualify`: the rebound test against the scipy reference, the verdict
logic, the uncertainty propagation, fit JSON handling, and the command line's errors.

References: tests/reference.py's scipy DOP853 with event location (independent of
jaxunilat) for rebound heights, and a delta-method propagation through central finite
differences of that reference for the Monte Carlo uncertainty.
"""

import json
import math

import numpy as np
import pytest
from jaxunilat.identify._apply._qualify import qualify, qualify_fit, rebound_height, verdict
from reference import FREE, BallParams, scipy_reference
from scipy.optimize import brentq

import jaxunilat
from jaxunilat._cli._main import main

M = 2.7e-3


def kv(e, t_c, m=M):
    """Inverse Kelvin–Voigt map: κ = m(π² + ln²e)/t_c², k_r = −2 m ln e / t_c."""
    return m * (math.pi**2 + math.log(e) ** 2) / t_c**2, -2 * m * math.log(e) / t_c


def reference_rebound(kappa, k_r, *, mass=M, drop=0.305, drag=0.12):
    """First apex after the first contact, scipy DOP853 + events, brentq on v."""
    p = BallParams(kappa, k_r, mass=mass, gravity=9.81, drag=drag, lower=0.0, upper=None)
    ref = scipy_reference(p, (drop, 0.0), 3 * math.sqrt(2 * drop / 9.81), max_step_free=0.05)
    assert ref.contacts, "no contact"
    for t0, t1, region, ev in ref.segments:
        if region == FREE and t0 >= ref.contacts[0].t_out:

            def v(s, ev=ev):
                return ev(np.array([s]))[1][0]

            t = brentq(v, t0, t1, xtol=1e-15)
            return float(ev(np.array([t]))[0][0])
    raise AssertionError("no rebound apex")


TRUTH = kv(0.935, 1.0e-3)  # the bundled drop data's ball: rebounds ~246.6 mm
LOW = kv(0.86, 1.0e-3)  # rebounds below 240 mm


@pytest.mark.parametrize("params", [TRUTH, LOW, kv(0.95, 0.6e-3), kv(0.90, 1.8e-3)])
def test_rebound_height_matches_scipy(params):
    assert rebound_height(*params) == pytest.approx(reference_rebound(*params), abs=1e-8)


def test_rebound_height_other_test_and_no_retrace():
    """Another drop height and mass; parameter values change, nothing retraces."""
    rebound_height(*TRUTH)  # compiled
    before = jaxunilat.trace_counts()
    h = rebound_height(*kv(0.9, 1.2e-3, 2.37e-3), mass=2.37e-3, drop=0.5, drag=0.122)
    assert h == pytest.approx(
        reference_rebound(*kv(0.9, 1.2e-3, 2.37e-3), mass=2.37e-3, drop=0.5, drag=0.122)
    )
    assert jaxunilat.trace_counts() == before


def test_reexported():
    from jaxunilat import identify

    assert identify.qualify is qualify and identify.qualify_fit is qualify_fit
    assert identify.rebound_height is rebound_height


def test_verdict_logic():
    assert verdict(0.25, (0.245, 0.255), 0.24, 0.26) == "PASS"
    assert verdict(0.25, (0.24, 0.26), 0.24, 0.26) == "PASS"  # limits included
    assert verdict(0.25, (0.235, 0.255), 0.24, 0.26) == "INCONCLUSIVE"
    assert verdict(0.25, (0.245, 0.27), 0.24, 0.26) == "INCONCLUSIVE"
    assert verdict(0.235, (0.23, 0.245), 0.24, 0.26) == "FAIL"
    assert verdict(0.265, (0.262, 0.268), 0.24, 0.26) == "FAIL"


def test_qualify_exact_parameters():
    good, bad = qualify(*TRUTH), qualify(*LOW)
    assert good.verdict == "PASS" and good.stderr == 0 and good.ci95 == (good.height, good.height)
    assert good.height == pytest.approx(reference_rebound(*TRUTH), abs=1e-8)
    assert good.restitution == pytest.approx(0.935, abs=1e-12)
    assert good.contact_time == pytest.approx(1e-3, rel=1e-12)
    assert bad.verdict == "FAIL" and bad.height < 0.240
    assert "PASS" in good.report() and "drag k = 0.12 s/m" in good.report()


def test_qualify_uncertainty_matches_delta_method():
    """Monte Carlo sd ≈ delta-method sd from finite differences of the scipy reference."""
    kappa, k_r = TRUTH
    s_log = np.array([0.02, 0.015])  # relative standard errors
    rho = 0.6
    res = qualify(kappa, k_r, stderr=(s_log[0] * kappa, s_log[1] * k_r), correlation=rho, samples=300, seed=1)
    step = 1e-3
    grad = []
    for i in range(2):
        up, down = np.log([kappa, k_r]), np.log([kappa, k_r])
        up[i] += step
        down[i] -= step
        grad.append((reference_rebound(*np.exp(up)) - reference_rebound(*np.exp(down))) / (2 * step))
    cov = np.outer(s_log, s_log) * np.array([[1, rho], [rho, 1]])
    sd = math.sqrt(np.array(grad) @ cov @ np.array(grad))
    # n = 300 draws: the sample sd has relative sd ~ 1/sqrt(600) = 4%; allow 4 of them.
    assert res.stderr == pytest.approx(sd, rel=0.16)
    lo, hi = res.ci95
    assert (hi - lo) == pytest.approx(2 * 1.96 * sd, rel=0.25)
    assert lo < res.height < hi
    assert res.samples == 300 and res.seed == 1
    # The same seed gives the same draws.
    again = qualify(
        kappa, k_r, stderr=(s_log[0] * kappa, s_log[1] * k_r), correlation=rho, samples=300, seed=1
    )
    assert again.ci95 == res.ci95


def test_qualify_inconclusive_and_window():
    kappa, k_r = TRUTH
    wide = qualify(kappa, k_r, stderr=(0.3 * kappa, 0.3 * k_r), correlation=0.0, samples=100)
    assert wide.verdict == "INCONCLUSIVE"
    assert wide.ci95[0] < 0.240 < wide.height < 0.260
    # A custom window that the same ball fails.
    assert qualify(kappa, k_r, min_height=0.25, max_height=0.27).verdict == "FAIL"


def fit_json(kappa=TRUTH[0], k_r=TRUTH[1], *, rel=(0.015, 0.0075), rho=0.99998, identifiable=True, **extra):
    e_val, t_c = 0.935, 1e-3
    fit = {
        "parameters": {
            "kappa": {"value": kappa, "stderr": rel[0] * kappa, "ci95": [0.97 * kappa, 1.03 * kappa]},
            "k_r": {"value": k_r, "stderr": rel[1] * k_r, "ci95": [0.985 * k_r, 1.015 * k_r]},
        },
        "derived": {
            "restitution": {"value": e_val, "stderr": 2e-4, "ci95": [e_val - 4e-4, e_val + 4e-4]},
            "contact_time": {"value": t_c, "stderr": 1e-5, "ci95": [0.98e-3, 1.02e-3]},
        },
        "identifiable": {"kappa": identifiable, "k_r": identifiable, "restitution": True},
        "correlation": [[1.0, rho], [rho, 1.0]],
        "converged": True,
        "mass": M,
        "data": "data/drop_trace.csv",
        "scene": "drop",
        "observe": "trace",
    }
    if not identifiable:
        for name in ("kappa", "k_r"):
            fit["parameters"][name]["stderr"] = None
            fit["parameters"][name]["ci95"] = None
    fit.update(extra)
    return fit


def test_qualify_fit_identifiable(tmp_path):
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit_json()))
    res = qualify_fit(path, samples=50)
    assert res.verdict == "PASS" and res.mass == M
    assert res.height == pytest.approx(reference_rebound(*TRUTH), abs=1e-8)
    # With correlation 0.99998 the rebound (set by e) is known far better than κ or k_r.
    assert 0 < res.stderr < 2e-5
    assert "fit's standard errors" in res.uncertainty and res.tc_sensitivity is None


def test_qualify_fit_restitution_only():
    """Apex-type fits: κ not identifiable; e with the 0.5–2 ms t_c prior, which barely matters."""
    fit = fit_json(kappa=3e6, k_r=40.0, identifiable=False)  # a meaningless point estimate
    res = qualify_fit(fit, samples=40)
    assert res.verdict == "PASS"
    assert res.restitution == pytest.approx(0.935, abs=1e-9)
    assert res.contact_time == pytest.approx(1e-3, rel=1e-9)  # geometric middle of the prior
    # t_c over its prior changes the height by < 1 mm (gravity and drag during contact).
    h_short = reference_rebound(*kv(0.935, 0.5e-3))
    h_long = reference_rebound(*kv(0.935, 2e-3))
    assert res.tc_sensitivity == pytest.approx(abs(h_long - h_short), abs=1e-8)
    assert res.tc_sensitivity < 1e-3
    # e's sd 2e-4 → height sd ≈ 2·h·sd(e)/e (h ∝ e² to first order), plus the small t_c part.
    assert res.stderr == pytest.approx(2 * res.height * 2e-4 / 0.935, rel=0.4)
    assert "only the restitution" in res.uncertainty


def test_qualify_fit_notes_and_errors(tmp_path):
    res = qualify_fit(fit_json(converged=False), samples=20)
    assert any("did not converge" in n for n in res.notes)
    neither = fit_json(identifiable=False)
    neither["identifiable"]["restitution"] = False
    with pytest.raises(ValueError, match="identifies neither"):
        qualify_fit(neither)
    with pytest.raises(ValueError, match="correlation = .* must be a square matrix"):
        qualify_fit(fit_json(correlation=[[1.0]]))
    with pytest.raises(ValueError, match="correlation = .* must be a square matrix"):
        qualify_fit(fit_json(correlation=[[1.0, None], [0.3, 1.0]]))
    # Fitted nuisance parameters extend the matrix: κ, k_r come first.
    three = [[1.0, 0.5, 0.1], [0.5, 1.0, 0.2], [0.1, 0.2, 1.0]]
    assert qualify_fit(fit_json(correlation=three), samples=20).uncertainty.count("correlation 0.5,") == 1
    with pytest.raises(ValueError, match="is not a correlation matrix"):
        qualify_fit(fit_json(correlation=[[1.0, 0.5], [0.2, 1.0]]))
    bad = fit_json()
    bad["parameters"]["kappa"]["value"] = -5.0
    with pytest.raises(ValueError, match=r"parameters.kappa.value = -5.0 is out of range"):
        qualify_fit(bad)
    with pytest.raises(ValueError, match="mass = -1 kg is out of range"):
        qualify_fit(fit_json(), mass=-1.0)
    with pytest.raises(ValueError, match="min_height = 0.26 m is not below max_height = 0.24 m"):
        qualify(*TRUTH, min_height=0.26, max_height=0.24)
    with pytest.raises(ValueError, match="samples = 5 is out of range"):
        qualify(*TRUTH, stderr=(1.0, 0.001), samples=5)
    with pytest.raises(ValueError, match="correlation = 1.5 is out of range"):
        qualify(*TRUTH, stderr=(1.0, 0.001), correlation=1.5)
    with pytest.raises(ValueError, match="does not rebound"):
        rebound_height(1e4, 20.0)  # ζ > 1: overdamped


def _run(capsys, *argv):
    code = main(["qualify", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_fit_and_json(tmp_path, capsys):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps(fit_json()))
    before = fit.read_bytes()
    out_json = tmp_path / "q.json"
    code, out, err = _run(capsys, str(fit), "--samples", "20", "--json", str(out_json))
    assert code == 0, err
    assert "verdict     PASS" in out and "drag k = 0.12 s/m" in out and "wall time" in out
    data = json.loads(out_json.read_text())
    assert data["verdict"] == "PASS" and data["samples"] == 20 and len(data["ci95"]) == 2
    assert data["height"] == pytest.approx(reference_rebound(*TRUTH), abs=1e-8)
    assert fit.read_bytes() == before
    code, out, _ = _run(capsys, "--kappa", str(LOW[0]), "--k-r", str(LOW[1]))
    assert code == 0 and "verdict     FAIL" in out


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["missing.json"], "missing.json: no such file"),
        (["{bad}"], "line 1: not valid JSON"),
        (["{fit}", "--kappa", "1e4", "--k-r", "0.2"], "either FIT.json or --kappa and --k-r, not both"),
        ([], "give FIT.json"),
        (["--kappa", "1e4"], "--kappa and --k-r go together"),
        (["--kappa", "1e4", "--k-r", "0.2", "--mass", "-0.001"], "mass = -0.001 kg is out of range"),
        (["--kappa", "-1e4", "--k-r", "0.2"], "kappa = -10000 N/m is out of range"),
        (["--kappa", "1e4", "--k-r", "0.2", "--min", "0.3"], "min_height = 0.3 m is not below"),
        (["--kappa", "1e4", "--k-r", "0.2", "--drag", "-1"], "drag = -1 s/m is out of range"),
        (["--kappa", "1e4", "--k-r", "0.2", "--drop", "0"], r"drop = 0 m is out of range"),
        (["{fit}", "--samples", "3"], "samples = 3 is out of range"),
        (["{fit}", "--json", "{fit}"], "--json"),
        (["{fit}", "--json", "{fit}"], "is the input FIT.json"),
        (["{fit}", "--json", "{dir}"], "is a directory"),
        (["{notfit}"], "not a fit JSON"),
        (["--kappa", "abc", "--k-r", "0.2"], "invalid float value"),
    ],
)
def test_cli_errors(tmp_path, capsys, argv, pattern):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps(fit_json()))
    (tmp_path / "bad.json").write_text('{"parameters": ')
    (tmp_path / "notfit.json").write_text("[1, 2]")
    names = {"{fit}": str(fit), "{bad}": str(tmp_path / "bad.json"), "{dir}": str(tmp_path)}
    names["{notfit}"] = str(tmp_path / "notfit.json")
    argv = [names.get(a, a) for a in argv]
    snapshot = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    code, out, err = _run(capsys, *argv)
    assert code == 2, (out, err)
    assert err.startswith("jaxunilat: error: "), err
    assert pattern in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == snapshot


def test_qualify_fit_refuses_a_damaged_or_foreign_fit():
    """κ missing or mistyped in a fit that says it identified κ is an error, never a silent
    fall-back to the restitution-only test; so are a damaged `identifiable` and a law the
    rebound test does not simulate."""
    missing = fit_json()
    del missing["parameters"]["kappa"]
    with pytest.raises(ValueError, match=r"parameters.kappa.value = None must be a finite number"):
        qualify_fit(missing)
    mistyped = fit_json()
    mistyped["parameters"]["kappa"]["value"] = "27000"
    with pytest.raises(ValueError, match=r"parameters.kappa.value = '27000' must be a number"):
        qualify_fit(mistyped)
    mistyped = fit_json(identifiable=False)
    mistyped["parameters"]["k_r"]["value"] = [0.36]
    with pytest.raises(ValueError, match=r"parameters.k_r.value = \[0.36\] must be a number"):
        qualify_fit(mistyped)
    no_verdicts = fit_json()
    del no_verdicts["identifiable"]
    with pytest.raises(ValueError, match="identifiable = None: expected true/false"):
        qualify_fit(no_verdicts)
    with pytest.raises(ValueError, match="law = 'hunt-crossley'"):
        qualify_fit(fit_json(law="hunt-crossley"))


def test_a_failed_test_run_names_the_drop_not_the_contact(capsys):
    """A drop the solver cannot finish is not blamed on κ and k_r; an overdamped contact is."""
    code, _, err = _run(capsys, "--kappa", str(TRUTH[0]), "--k-r", str(TRUTH[1]), "--drop", "1e6")
    assert code == 2 and "drop = 1e+06 m failed" in err and "kappa" not in err
    with pytest.raises(ValueError, match=r"does not rebound \(overdamped contact\)"):
        rebound_height(1e4, 20.0)
