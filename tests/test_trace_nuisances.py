"""A trace's length scale and contact level (`scale`, `level`) as nuisance parameters.

A video trace is x_data = level + scale · x(t): its pixels-to-metres factor comes from a
ruler that perspective puts off, and its floor is set by hand. The synthetic trace here
is a 30 fps video of a drop from 0.30 m, made by the independent scipy reference
(`tests/reference.py`: DOP853 with event location, no jaxunilat), scaled by 1.03, shifted
by 2 mm, with 1 mm (about one pixel) of noise; its x0 is its first sample, as `import
video` writes it, so x0 and v0 are fitted too. The true parameters are not the paper's:
κ = 1.6e4 N/m, k_r = 0.15 N·s/m on a 2.7 g ball with drag 0.12 s/m (e ≈ 0.9648).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from reference import BallParams, kelvin_voigt_restitution, scipy_reference

from jaxunilat import identify
from jaxunilat._cli._main import main

KAPPA, K_R, MASS, DRAG = 1.6e4, 0.15, 2.7e-3, 0.12
E_TRUE = kelvin_voigt_restitution(KAPPA, K_R, MASS)
SCALE, LEVEL, NOISE, FPS = 1.03, 0.002, 1e-3, 30.0


@pytest.fixture(scope="module")
def reference():
    params = BallParams(kappa=KAPPA, k_r=K_R, mass=MASS, drag=DRAG, lower=0.0, upper=None)
    return scipy_reference(params, (0.30, 0.0), 3.05, rtol=1e-12, atol=1e-14)


def _video(reference, seed, *, scale=SCALE, level=LEVEL, t1=3.0, source=None):
    t = np.arange(0.0, t1, 1.0 / FPS)
    x = level + scale * reference(t)[0] + np.random.default_rng(seed).normal(0.0, NOISE, t.size)
    return identify.Dataset(
        scene="drop", observe="trace", mass=MASS, drag=DRAG, x0=float(x[0]), v0=0.0, noise=NOISE, t=t, x=x,
        source=source,
    )  # fmt: skip


def _covers(entry, truth):
    lo, hi = entry.ci95
    return lo <= truth <= hi


def test_free_scale_and_level_recover_the_calibration_and_e_frozen_ones_bias_it(reference):
    data = _video(reference, seed=1)
    free = identify.fit(data, starts=1)
    print("\n" + free.report())
    assert free.converged, free.message
    assert {"scale", "level"} <= set(free.free)  # fitted by default for a trace
    assert _covers(free.params["scale"], SCALE), free.params["scale"]
    assert _covers(free.params["level"], LEVEL), free.params["level"]
    e = free.derived["restitution"]
    assert _covers(e, E_TRUE), (e, E_TRUE)
    assert free.goodness["consistent"] is True

    # Held at (1, 0), the same frames cannot be fitted: the χ² test fails, e misses the
    # truth by far more than the free fit does, and the contact time follows the
    # hand-set calibration (κ runs off: t_c a twentieth of the true 1.29 ms).
    held = identify.fit(data, starts=1, freeze=("scale", "level"))
    print("\n" + held.report())
    assert "scale" not in held.free and "level" not in held.free
    assert held.params["scale"].value == 1.0 and held.params["level"].value == 0.0
    assert held.goodness["consistent"] is False
    bias = held.derived["restitution"].value - E_TRUE
    print(f"e: free {e.value:.5f} +/- {e.stderr:.5f}, held {held.derived['restitution'].value:.5f}, "
          f"truth {E_TRUE:.5f}, bias {bias:+.5f}; t_c held {held.derived['contact_time'].value * 1e3:.3g} ms")  # fmt: skip
    # (e's interval counts the trace's few bounces, so it is no yardstick for a bias here.)
    assert abs(bias) > 5.0 * abs(e.value - E_TRUE)
    assert held.derived["contact_time"].value < 0.3e-3


def test_scale_and_level_columns_are_closed_form_and_take_no_runs(reference):
    """level + scale · x_model: the level's column is 1/σ and the scale's x_model/σ, read
    off the point's own run; checked against central differences of explicit runs, and
    only κ and k_r take runs (5 per call)."""
    from jaxunilat.identify._fit._problem import PARAMETERS, evaluate_rows, to_z
    from jaxunilat.identify._fit._setup import build

    data = _video(reference, seed=3, t1=1.2)
    setup = build(
        [data], law="kelvin-voigt", nuisance=("scale", "level"), freeze=(), initial={}, bounds={}, tol=1e-10
    )
    evaluator = setup.evaluator.with_(prior=False)
    assert evaluator.free == [PARAMETERS.index(n) for n in ("kappa", "k_r", "scale", "level")]
    assert evaluator.rows == 5
    z = to_z(dict(kappa=KAPPA, k_r=K_R, drag=DRAG, x0=0.30, v0=0.0, offset=0.0, scale=SCALE, level=LEVEL))
    r, jac, ok = evaluator(z)
    assert ok and jac.shape == (data.num_rows, 4) and np.all(np.isfinite(jac))
    np.testing.assert_allclose(jac[:, 3], 1.0 / NOISE, rtol=0, atol=0)
    h = 1e-3
    zs = np.repeat(z[None, :], 5, axis=0)
    for row, (name, step) in enumerate((("scale", h), ("scale", -h), ("level", h), ("level", -h))):
        zs[row, PARAMETERS.index(name)] += step
    res, ok_rows = evaluate_rows(setup.evaluator.groups[0].problem, zs[None], np.asarray(False))
    res = np.asarray(res)[0]
    assert np.all(np.asarray(ok_rows))
    np.testing.assert_allclose(jac[:, 2], (res[0] - res[1]) / (2 * h), rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(jac[:, 3], (res[2] - res[3]) / (2 * h), rtol=1e-7)
    np.testing.assert_allclose(r, res[4], rtol=0, atol=0)


def test_measured_calibration_is_held_and_freeze_is_respected(reference):
    from jaxunilat.identify._fit._options import default_nuisance
    from jaxunilat.identify._fit._setup import build

    data = _video(reference, seed=4, t1=1.2)

    def fitted(datasets, freeze=()):
        nuisance, note = default_nuisance(datasets, (), freeze)
        setup = build(datasets, law="kelvin-voigt", nuisance=nuisance, freeze=freeze, initial={}, bounds={},
                      tol=1e-10)  # fmt: skip
        return [name + ("" if f is None else str(f)) for name, f in
                (setup.layout.names()[j] for j in setup.free)], note  # fmt: skip

    names, note = fitted([data])
    assert names == ["kappa", "k_r", "x00", "offset0", "scale0", "level0"]
    assert "scale, level fitted" in note and "--freeze scale,level" in note
    assert fitted([data], freeze=("level",))[0] == ["kappa", "k_r", "x00", "offset0", "scale0"]
    measured = dataclasses.replace(data, measured=("scale", "level"))
    names, note = fitted([measured])
    assert names == ["kappa", "k_r", "x00", "offset0"] and "scale" not in note
    # In a joint fit the file that measured its calibration holds it; the other fits its own.
    names, _ = fitted([measured, _video(reference, seed=5, t1=1.2)])
    assert [n for n in names if n.startswith(("scale", "level"))] == ["scale1", "level1"]


def test_scale_on_impact_onsets_is_refused(tmp_path, capsys):
    onsets = np.array([0.30, 0.77, 1.22, 1.66, 2.08, 2.49])
    path = tmp_path / "onsets.csv"
    identify.write_dataset(
        path,
        identify.Dataset(scene="drop", observe="impacts", mass=MASS, drag=DRAG, x0=0.3, v0=0.0, t=onsets),
    )
    code = main(["identify", str(path), "--fit", "scale"])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxunilat: error:"), err
    assert "'scale'" in lines[0] and "applies to traces" in lines[0] and "impacts" in lines[0]
    with pytest.raises(ValueError, match="'level'.*applies to traces"):
        identify.fit(identify.load_dataset(path), nuisance=("level",))


def test_report_and_json_show_each_fitted_calibration(reference):
    files = [
        _video(reference, seed=6, t1=2.0, source="cam a"),
        _video(reference, seed=7, scale=0.97, level=-0.003, t1=2.0, source="cam b"),
    ]
    result = identify.fit(files, starts=1)
    report = result.report()
    print("\n" + report)
    assert result.converged, result.message
    table = result.file_table()
    for f, (scale, level) in enumerate(((SCALE, LEVEL), (0.97, -0.003))):
        assert table[f]["scale"]["status"] == "fitted" and table[f]["level"]["status"] == "fitted"
        assert (
            abs(table[f]["scale"]["value"] - scale) < 0.02 and abs(table[f]["level"]["value"] - level) < 0.005
        )
    assert np.isfinite(table[0]["scale"]["stderr"]) and table[0]["scale"]["stderr"] > 0
    header = report[report.index("\n[[Files]]") + 1 :].splitlines()[1]
    assert "scale" in header and "level (mm)" in header
    assert "scale, level fitted per file" in report or "x0, v0, scale, level fitted per file" in report
    doc = json.loads(json.dumps(result.to_json_dict(), allow_nan=False))
    assert {"scale", "level"} <= set(doc["fitted"]) and {"scale", "level"} <= set(doc["nuisance"])
    assert doc["files"][1]["scale"]["status"] == "fitted"
    # One file: the [[Variables]] lines carry the estimate and its 95% interval.
    one = identify.fit(files[0], starts=1).report()
    line = next(s for s in one.splitlines() if s.strip().startswith("scale"))
    assert "95% CI [" in line
