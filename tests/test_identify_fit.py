"""identify.fit against data made by the independent scipy reference (tests/reference.py).

The true parameters are not the paper's: κ = 1.6e4 N/m, k_r = 0.15 N·s/m on a 2.7 g
ball (e ≈ 0.955, t_c ≈ 1.3 ms), dropped from 0.30 m with drag 0.12 s/m onto x = 0.
Every data set is the scipy DOP853 + event-location solution plus Gaussian noise.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from reference import BallParams, kelvin_voigt_contact_time, kelvin_voigt_restitution, scipy_reference

import jaxunilat as ju
from jaxunilat import identify
from jaxunilat._cli._main import main

TRUE = dict(kappa=1.6e4, k_r=0.15)
MASS, DRAG, X0 = 2.7e-3, 0.12, 0.30
E_TRUE = kelvin_voigt_restitution(TRUE["kappa"], TRUE["k_r"], MASS)
TC_TRUE = kelvin_voigt_contact_time(TRUE["kappa"], TRUE["k_r"], MASS)
OFFSET = 0.0412  # the recording's clock minus the release time, s


@pytest.fixture(scope="module")
def reference():
    params = BallParams(kappa=TRUE["kappa"], k_r=TRUE["k_r"], mass=MASS, drag=DRAG, lower=0.0, upper=None)
    return scipy_reference(params, (X0, 0.0), 4.0, rtol=1e-12, atol=1e-14)


def _dataset(observe, **columns):
    return identify.Dataset(
        scene="drop", observe=observe, mass=MASS, drag=DRAG, x0=X0, v0=0.0, source="test", **columns
    )


def _trace(reference, seed, *, t1=1.5, rate=1000.0, noise=5e-4):
    t = np.arange(0.0, t1 + 0.5 / rate, 1.0 / rate)
    x, _ = reference(t)
    x = x + np.random.default_rng(seed).normal(0.0, noise, t.shape)
    return _dataset("trace", t=t, x=np.round(x, 7), noise=noise)


def _impacts(reference, seed, *, n=10, noise=2e-5):
    t = reference.impact_times()[:n] + OFFSET
    return _dataset("impacts", t=t + np.random.default_rng(seed).normal(0.0, noise, n), noise=noise)


def _apex_heights(reference, n):
    """Rebound apex heights from the reference: the max of x over each flight (1e-6 s grid)."""
    heights = []
    contacts = reference.contacts
    for before, after in zip(contacts[:-1], contacts[1:], strict=False):
        ts = np.arange(before.t_out, after.t_in, 1e-6)
        heights.append(float(np.max(reference(ts)[0])))
        if len(heights) == n:
            break
    return np.asarray(heights)


def _covers(entry, truth):
    lo, hi = entry.ci95
    return lo <= truth <= hi


def test_trace_recovers_kappa_and_k_r(reference):
    result = identify.fit(_trace(reference, seed=1), starts=2)
    print("\n" + result.report())
    assert result.converged, result.message
    for name, truth in TRUE.items():
        entry = result.params[name]
        assert abs(entry.value / truth - 1) <= 0.05, (name, entry, truth)
        assert _covers(entry, truth), (name, entry, truth)
    assert result.identifiable["kappa"] and result.identifiable["k_r"] and result.identifiable["restitution"]
    # The noise level is consistent with the file's σ (reduced χ² near 1).
    assert 0.8 <= result.chi2 / (len(result.residuals) - 2) <= 1.2
    assert result.goodness["consistent"] is True


def test_impacts_without_their_offset_fail_the_chi2_test_and_identify_nothing(reference):
    """Acoustic impact times whose clock is 41 ms off the release, fitted with the offset
    held at 0: the χ² test against the file's σ must fail and say so, and κ, k_r and t_c
    (which the onsets' absolute times would carry) must not be called identifiable. The
    restitution, read from the ratios of successive flights (which no clock offset moves),
    may be: then its interval covers the truth."""
    import math

    result = identify.fit(_impacts(reference, seed=2), starts=1, freeze=("offset",))
    report = result.report()
    print("\n" + report)
    g = result.goodness
    assert g["reduced_chi2"] > 100 and g["consistent"] is False and g["p_value"] < 1e-3
    assert not any(result.identifiable[k] for k in ("kappa", "k_r", "contact_time"))
    true_e = math.exp(-math.pi * _zeta() / math.sqrt(1.0 - _zeta() ** 2))  # Kelvin-Voigt
    lo, hi = result.derived["restitution"].ci95
    assert not result.identifiable["restitution"] or lo <= true_e <= hi
    assert "WARNING: the model does not fit the data" in report and "leave out --freeze offset" in report
    doc = result.to_json_dict()
    assert doc["goodness_of_fit"]["consistent"] is False
    assert not any(doc["identifiable"][k] for k in ("kappa", "k_r", "contact_time"))


def _zeta() -> float:
    """The true damping ratio of the reference's contact, k_r / (2 √(κ m))."""
    return TRUE["k_r"] / (2.0 * (TRUE["kappa"] * MASS) ** 0.5)


def _chi2_sf_even(x: float, dof: int) -> float:
    """P(χ² ≥ x) for an even number of degrees of freedom, in closed form:
    e^(−x/2) Σ_{i < dof/2} (x/2)^i / i! (the tail of a Poisson count)."""
    assert dof % 2 == 0
    logs = [i * math.log(x / 2) - math.lgamma(i + 1) for i in range(dof // 2)]
    top = max(logs)
    return math.exp(top - x / 2) * sum(math.exp(v - top) for v in logs)


@pytest.mark.parametrize(("chi2", "n", "p"), [(3.0, 12, 2), (25.0, 14, 2), (1550.0, 1502, 2), (40.0, 4, 2)])
def test_goodness_of_fit_p_value_matches_the_closed_form(chi2, n, p):
    from jaxunilat.identify._fit._uncertainty import goodness_of_fit

    g = goodness_of_fit(chi2, n, p, sigma_known=True)
    expected = _chi2_sf_even(chi2, n - p)
    assert g["dof"] == n - p
    assert g["p_value"] == pytest.approx(expected, rel=1e-9, abs=1e-300)
    assert g["consistent"] == (expected >= 1e-3)
    untested = goodness_of_fit(chi2, n, p, sigma_known=False)
    assert untested["p_value"] is None and untested["consistent"] is None


def test_noise_estimated_from_residuals_when_the_file_states_none(reference):
    import dataclasses

    known = _trace(reference, seed=7)
    unknown = dataclasses.replace(known, noise=None)
    with_sigma = identify.fit(known, starts=1)
    without = identify.fit(unknown, starts=1)
    assert without.sigma_source == "residuals" and with_sigma.sigma_source == "file"
    # s² = Σr²/(N − p) estimates the generating σ = 0.5 mm (N = 1501: to a few percent).
    assert without.sigma == pytest.approx(5e-4, rel=0.1)
    # The same optimum to well below a standard error (~1.6%): the two fits take different
    # LM paths (the prior row weighs differently against the nominal and the stated sigma).
    assert without.kappa == pytest.approx(with_sigma.kappa, rel=1e-4)
    ratio = without.params["kappa"].stderr / with_sigma.params["kappa"].stderr
    assert ratio == pytest.approx(without.sigma / 5e-4, rel=1e-3)


def test_impacts_recover_restitution_with_unknown_offset(reference):
    result = identify.fit(_impacts(reference, seed=2), nuisance=("offset",), starts=2)
    print("\n" + result.report())
    assert result.converged, result.message
    assert abs(result.derived["restitution"].value - E_TRUE) <= 0.005
    assert abs(result.params["offset"].value - OFFSET) <= 1e-3
    assert _covers(result.derived["restitution"], E_TRUE)
    assert result.goodness["consistent"] is True


def test_offset_column_is_closed_form_and_takes_no_runs(reference):
    """The offset only shifts the predicted onsets: its Jacobian column is 1/σ, from no run.

    Checked against a central difference of residuals from explicit runs at offset ± h,
    and the κ, k_r columns still come from 2 runs each (5 runs per call, not 7).
    """
    from jaxunilat.identify._fit._problem import PARAMETERS, evaluate_rows, to_z
    from jaxunilat.identify._fit._setup import build

    data = _impacts(reference, seed=7, n=8)
    setup = build(
        [data], law="kelvin-voigt", nuisance=("offset",), freeze=(), initial={}, bounds={}, tol=1e-10
    )
    evaluator = setup.evaluator.with_(prior=False)
    problem = setup.evaluator.groups[0].problem
    z = to_z(dict(kappa=TRUE["kappa"], k_r=TRUE["k_r"], drag=DRAG, x0=X0, v0=0.0, offset=OFFSET))
    assert evaluator.free == [PARAMETERS.index(n) for n in ("kappa", "k_r", "offset")]
    assert evaluator.rows == 5
    r, jac, ok = evaluator(z)
    assert ok and jac.shape == (8, 3) and np.all(np.isfinite(jac))

    h, i = 1e-4, PARAMETERS.index("offset")
    zs = np.repeat(z[None, :], 5, axis=0)
    zs[0, i] += h
    zs[1, i] -= h
    res, ok_rows = evaluate_rows(problem, zs[None], np.asarray(False))
    res, ok_rows = np.asarray(res)[0], np.asarray(ok_rows)[0]
    assert np.all(np.asarray(ok_rows))
    np.testing.assert_allclose(jac[:, 2], (res[0] - res[1]) / (2 * h), rtol=1e-8)
    np.testing.assert_allclose(r, res[2], rtol=0, atol=0)
    # κ and k_r move the onsets (later bounces more): their columns are real differences.
    assert np.all(np.abs(jac[1:, :2]) > 0)


def test_apex_heights_identify_e_but_not_kappa(reference):
    heights = _apex_heights(reference, 8)
    noise = 1e-3
    data = _dataset(
        "apex", h=heights + np.random.default_rng(3).normal(0.0, noise, len(heights)), noise=noise
    )
    result = identify.fit(data, starts=2)
    print("\n" + result.report())
    assert abs(result.derived["restitution"].value - E_TRUE) <= 0.01
    assert result.identifiable["restitution"]
    assert not result.identifiable["kappa"]
    assert not result.identifiable["k_r"]
    # Apex heights leave log κ essentially undetermined: its 95% interval spans over a decade.
    kappa = result.params["kappa"]
    assert kappa.ci95[1] / kappa.ci95[0] > 10


@pytest.mark.slow
def test_confidence_intervals_cover_the_truth(reference):
    """Over 20 noise realizations, the 95% CIs of κ and e cover the truth about 95% of the time.

    With n = 20 and p = 0.95, fewer than 16 covers has probability 0.3%.
    """
    covers = {"kappa": 0, "k_r": 0, "restitution": 0}
    for seed in range(20):
        result = identify.fit(_impacts(reference, seed=100 + seed, n=8), nuisance=("offset",), starts=1)
        covers["kappa"] += _covers(result.params["kappa"], TRUE["kappa"])
        covers["k_r"] += _covers(result.params["k_r"], TRUE["k_r"])
        covers["restitution"] += _covers(result.derived["restitution"], E_TRUE)
    print("\ncoverage of 20:", covers)
    assert all(count >= 16 for count in covers.values()), covers


def test_frozen_parameter_and_derived_contact_time(reference):
    data = _trace(reference, seed=4, t1=1.0)
    result = identify.fit(data, freeze=("k_r",), initial={"k_r": TRUE["k_r"]}, starts=1)
    assert result.params["k_r"].value == pytest.approx(TRUE["k_r"], rel=1e-12)
    assert result.params["k_r"].stderr == 0.0
    assert result.free == ("kappa", "scale", "level")  # a trace's calibration is fitted by default
    assert abs(result.kappa / TRUE["kappa"] - 1) <= 0.05
    assert abs(result.derived["contact_time"].value / TC_TRUE - 1) <= 0.05


def test_no_retrace_between_fits_of_the_same_shape(reference):
    identify.fit(_impacts(reference, seed=5, n=8), nuisance=("offset",), starts=1)
    before = dict(ju.trace_counts())
    result = identify.fit(_impacts(reference, seed=6, n=8), nuisance=("offset",), starts=2)
    assert result.simulations > 2
    assert ju.trace_counts() == before


def test_json_schema_and_cli(tmp_path, reference):
    heights = _apex_heights(reference, 6)
    data = _dataset("apex", h=heights, noise=1e-3)
    path = tmp_path / "apex.csv"
    identify.write_dataset(path, data)
    before = path.read_bytes()
    out = tmp_path / "fit.json"
    assert main(["identify", str(path), "--json", str(out), "--starts", "1"]) == 0
    assert path.read_bytes() == before
    doc = json.loads(out.read_text())
    assert set(doc) >= {"parameters", "derived", "identifiable", "correlation", "converged"}
    assert set(doc["parameters"]) == {"kappa", "k_r"}
    assert set(doc["derived"]) == {"restitution", "contact_time"}
    for entry in list(doc["parameters"].values()) + list(doc["derived"].values()):
        assert set(entry) == {"value", "stderr", "ci95"} and len(entry["ci95"]) == 2
    assert set(doc["identifiable"]) >= {"kappa", "k_r", "restitution"}
    assert doc["identifiable"]["kappa"] is False and doc["identifiable"]["restitution"] is True
    assert len(doc["correlation"]) == 2 and all(len(row) == 2 for row in doc["correlation"])
    assert isinstance(doc["converged"], bool)
    assert math.isclose(doc["mass"], MASS)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(nuisance=("spin",)), "nuisance"),
        (dict(nuisance=("offset",)), "offset"),
        (dict(freeze=("kappa", "k_r")), "nothing to fit"),
        (dict(starts=0), "starts"),
        (dict(method="bfgs"), "method"),
        (dict(bounds={"kappa": (2.0, 1.0)}), "bounds"),
        (dict(initial={"kappa": -1.0}), "kappa"),
        (dict(optimizer="adam"), "optimizer"),
    ],
)
def test_bad_fit_arguments(kwargs, match):
    data = _dataset("apex", h=np.array([0.25, 0.2, 0.16]))
    with pytest.raises(ValueError, match=match):
        identify.fit(data, **kwargs)


def test_cli_bad_fit_flag(capsys):
    assert main(["identify", "--fit", "spin"]) == 2
    assert "--fit" in capsys.readouterr().err
