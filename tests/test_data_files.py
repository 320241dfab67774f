"""The bundled data sets in data/: they load, are documented, and match their stated truth.

The consistency checks are independent of jaxunilat: the stated true parameters (from
data/README.md, typed here, not imported from data/generate.py) are simulated with the
scipy DOP853 + event-location reference of tests/reference.py, and the residuals of the
noisy files must look like the stated noise.
"""

import math
import os
import shutil

import numpy as np
import pytest
from jaxunilat.identify import load_dataset
from reference import FREE, BallParams, scipy_reference
from scipy.optimize import brentq

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")


def _is_data_file(name: str) -> bool:
    """A jaxunilat-data file (the raw recordings for `jaxunilat import` are not)."""
    if not name.endswith(".csv"):
        return False
    with open(os.path.join(DATA, name), encoding="utf-8") as f:
        return f.readline().startswith("# jaxunilat-data")


FILES = sorted(f for f in os.listdir(DATA) if _is_data_file(f))


def kv_parameters(e, t_c, m):
    """The inverse Kelvin–Voigt map: κ = m(π² + ln²e)/t_c², k_r = −2 m ln e / t_c."""
    return m * (math.pi**2 + math.log(e) ** 2) / t_c**2, -2 * m * math.log(e) / t_c


# The truth stated in data/README.md.
DROP = BallParams(
    *kv_parameters(0.935, 1.0e-3, 2.7e-3), mass=2.7e-3, gravity=9.81, drag=0.12, lower=0.0, upper=None
)
RACKETS = BallParams(
    *kv_parameters(0.92, 1.2e-3, 2.37e-3), mass=2.37e-3, gravity=9.81, drag=0.122, lower=-0.4, upper=0.4
)
OFFSET = 0.0731


@pytest.fixture(scope="module")
def drop_reference():
    # One wall below: no step can jump over an excursion, so free flight needs no step cap.
    return scipy_reference(DROP, (0.305, 0.0), 4.0, max_step_free=0.05)


def test_expected_files_present():
    assert {"drop_apex.csv", "drop_impacts.csv", "drop_trace.csv", "rackets_trace.csv"} <= set(FILES)


@pytest.mark.parametrize("name", FILES)
def test_files_load_and_are_documented(name):
    path = os.path.join(DATA, name)
    ds = load_dataset(path)
    assert os.path.getsize(path) < 200_000
    assert ds.source is not None and ds.source.startswith("SYNTHETIC")
    assert ds.noise is not None
    with open(os.path.join(DATA, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    assert f"`{name}`" in readme
    assert "SYNTHETIC" in readme


def test_stated_parameters_match_readme():
    """The κ, k_r printed in data/README.md are the map of the stated (e, t_c)."""
    with open(os.path.join(DATA, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    for p in (DROP, RACKETS):
        assert f"{p.kappa!r} N/m, {p.k_r!r} N·s/m" in readme


def _check_noise(residual, sd, *, tol_sd):
    n = len(residual)
    assert abs(np.mean(residual)) < 4 * sd / math.sqrt(n), (np.mean(residual), sd)
    assert abs(np.std(residual) / sd - 1) < tol_sd, (np.std(residual), sd)


def test_drop_trace_consistent_with_truth(drop_reference):
    ds = load_dataset(os.path.join(DATA, "drop_trace.csv"))
    assert (ds.scene, ds.observe, ds.mass, ds.drag, ds.x0, ds.v0) == (
        "drop",
        "trace",
        2.7e-3,
        0.12,
        0.305,
        0.0,
    )
    assert ds.num_rows == 2501 and ds.t[-1] == 2.5 and np.allclose(np.diff(ds.t), 1e-3)
    x, _ = drop_reference(ds.t)
    # n = 2501: the sample sd has a relative sd of 1/sqrt(2n) = 1.4%; allow 4 of them.
    _check_noise(ds.x - x, ds.noise, tol_sd=0.06)
    # A wrong truth is detected: the paper-like 10% softer contact shifts the bounces.
    other = BallParams(
        DROP.kappa * 0.9, DROP.k_r, mass=2.7e-3, gravity=9.81, drag=0.12, lower=0.0, upper=None
    )
    wrong = scipy_reference(other, (0.305, 0.0), 1.0, max_step_free=0.05)(ds.t[:1001])[0]
    assert np.std(ds.x[:1001] - wrong) > 1.5 * ds.noise


def test_drop_trace_rebounds_within_ittf(drop_reference):
    """The stated truth is an ITTF-compliant ball: first rebound 240–260 mm from 305 mm."""
    h = _rebound_apexes(drop_reference)
    assert 0.240 < h[0][1] < 0.260


def _rebound_apexes(ref):
    """(t, x) at each free-flight apex after the first contact, by brentq on v."""
    out = []
    for t0, t1, region, ev in ref.segments:
        if region != FREE or t0 == 0.0 or t1 <= t0:
            continue
        v0, v1 = ev(np.array([t0]))[1][0], ev(np.array([t1]))[1][0]
        if v0 > 0 > v1:
            t = brentq(lambda s, ev=ev: ev(np.array([s]))[1][0], t0, t1, xtol=1e-15)
            out.append((t, ev(np.array([t]))[0][0]))
    return out


def test_drop_impacts_consistent_with_truth(drop_reference):
    ds = load_dataset(os.path.join(DATA, "drop_impacts.csv"))
    true = drop_reference.impact_times()
    true = true[true <= 4.0]
    assert ds.num_rows == len(true) == 14
    residual = ds.t - OFFSET - true
    # n = 14: the sample sd is within ±50% of the stated sd with probability > 0.999.
    _check_noise(residual, ds.noise, tol_sd=0.5)
    assert np.max(np.abs(residual)) < 4 * ds.noise


def test_drop_apex_consistent_with_truth(drop_reference):
    ds = load_dataset(os.path.join(DATA, "drop_apex.csv"))
    apexes = np.array(_rebound_apexes(drop_reference))
    assert ds.num_rows == len(apexes) == 14
    np.testing.assert_allclose(ds.t, apexes[:, 0], atol=0.5e-3 + 1e-9)  # rounded to 1 ms
    residual = ds.h - apexes[:, 1]
    _check_noise(residual, ds.noise, tol_sd=0.5)


def test_rackets_trace_consistent_with_truth():
    ds = load_dataset(os.path.join(DATA, "rackets_trace.csv"))
    assert (ds.scene, ds.gap, ds.x0, ds.v0, ds.mass, ds.drag) == ("rackets", 0.8, -0.4, -8.0, 2.37e-3, 0.122)
    assert ds.num_rows == 1501 and ds.t[-1] == 1.5
    ref = scipy_reference(RACKETS, (ds.x0, ds.v0), 1.5)
    assert sum(c.wall == "upper" for c in ref.contacts) >= 2  # both rackets are seen
    _check_noise(ds.x - ref(ds.t)[0], ds.noise, tol_sd=0.08)


def _generator():
    import importlib.util

    spec = importlib.util.spec_from_file_location("_data_generate", os.path.join(DATA, "generate.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generator_states_the_readme_truth():
    """data/generate.py simulates exactly the parameters data/README.md states."""
    gen = _generator()
    assert gen.true_parameters(gen.DROP) == pytest.approx((DROP.kappa, DROP.k_r), rel=1e-14)
    assert gen.true_parameters(gen.RACKETS) == pytest.approx((RACKETS.kappa, RACKETS.k_r), rel=1e-14)
    assert (gen.DROP["mass"], gen.DROP["drag"], gen.DROP["x0"], gen.DROP["v0"]) == (2.7e-3, 0.12, 0.305, 0.0)
    assert gen.DROP_IMPACTS["offset"] == OFFSET and gen.TOL == 1e-12
    with open(os.path.join(DATA, "README.md"), encoding="utf-8") as f:
        assert f"SeedSequence({gen.SEED})" in f.read()


def test_generator_check_detects_changes(tmp_path):
    """`generate.py --check`'s comparison: identical files pass, a changed digit or key fails.

    (The full `--check`, which re-simulates, takes ~30 s: run `python data/generate.py --check`.)
    """
    gen = _generator()
    fresh = {name: load_dataset(os.path.join(DATA, name)) for name in FILES}
    for name in FILES:
        shutil.copyfile(os.path.join(DATA, name), tmp_path / name)
    assert gen.check(fresh, str(tmp_path)) == []
    text = (tmp_path / "drop_trace.csv").read_text()
    # A last-digit rounding flip (1 µm) is within print precision; 3 µm is not.
    row = text.splitlines()[11]
    t, x = row.split(",")
    (tmp_path / "drop_trace.csv").write_text(text.replace(row, f"{t},{float(x) + 1e-6:.6f}"))
    assert gen.check(fresh, str(tmp_path)) == []
    (tmp_path / "drop_trace.csv").write_text(text.replace(row, f"{t},{float(x) + 3e-6:.6f}"))
    assert gen.check(fresh, str(tmp_path)) == ["drop_trace.csv: column x differs by up to 3e-06"]
    (tmp_path / "drop_trace.csv").write_text(text.replace("# drag = 0.12", "# drag = 0.13"))
    assert gen.check(fresh, str(tmp_path)) == ["drop_trace.csv: drag = 0.13, regenerated 0.12"]
    (tmp_path / "drop_apex.csv").unlink()
    assert "drop_apex.csv: missing" in gen.check(fresh, str(tmp_path))
