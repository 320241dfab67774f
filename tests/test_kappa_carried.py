"""κ only where the data carry it.

A contact stiffness is the quantity this project exists to identify, and reporting a κ
its data do not carry is the worst result it can give. These tests check the rules that
stand between a fit and an "identifiable" κ (or k_r, or contact time t_c):

- a value the importer *estimated* (the release height of a phone recording) is fitted,
  not held: held at a 6% error, the fit put the error into t_c;
- a fit inconsistent with its stated noise never calls κ, k_r or t_c identifiable, whatever
  its Gauss–Newton interval says (a 1 mm error in a stated release height moves κ from
  27 000 to 13 000 N/m with a ±2% interval);
- the profile likelihood of κ must close on both sides.

The references are the synthetic truths written in data/README.md (e = 0.955, t_c = 0.7 ms
for the phone recording; κ = 26 660 N/m for the drop trace), not this code's output.
"""

import json
import pathlib

import numpy as np
import pytest
from jaxunilat.identify._fit._outcome import Profile
from jaxunilat.identify._fit._profile import profile_closes

from jaxunilat import identify
from jaxunilat._cli._main import main

#: data/README.md: the phone recording's mean restitution and contact time.
PHONE_E, PHONE_T_C = 0.955, 0.7e-3


@pytest.fixture
def bundled() -> pathlib.Path:
    """The bundled synthetic data folder, data/."""
    return pathlib.Path(__file__).resolve().parents[1] / "data"


def _run(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_the_readme_phone_recipe_gives_e_and_no_confident_kappa(tmp_path, capsys, bundled):
    """`jaxunilat import wav data/phone_drop.wav --ball pingpong --out drop.csv`, then `jaxunilat identify drop.csv`
    (the README's recipe, verbatim): e within 0.005 of the truth, exit 0, and κ either not
    identifiable or with an interval that holds the truth."""
    data, fit_json = tmp_path / "drop.csv", tmp_path / "fit.json"
    argv = ["import", "wav", str(bundled / "phone_drop.wav"), "--ball", "pingpong", "--out", str(data)]
    code, out, err = _run(argv, capsys)
    assert code == 0, out + err
    assert "# estimated = x0" in data.read_text(), "the importer must say that it estimated x0"
    code, out, err = _run(["--no-cache", "identify", str(data), "--json", str(fit_json)], capsys)
    assert code == 0, out + err
    fit = json.loads(fit_json.read_text())
    e = fit["derived"]["restitution"]
    assert abs(e["value"] - PHONE_E) < 0.005, out
    assert e["ci95"][0] < PHONE_E < e["ci95"][1], out
    assert "x0" in fit["fitted"], "an estimated x0 must be fitted"
    t_c = fit["derived"]["contact_time"]
    if fit["identifiable"]["contact_time"]:
        assert t_c["ci95"][0] <= PHONE_T_C <= t_c["ci95"][1], out
    if fit["identifiable"]["kappa"]:
        kappa = 0.0027 * (np.pi**2 + np.log(PHONE_E) ** 2) / PHONE_T_C**2
        assert fit["parameters"]["kappa"]["ci95"][0] <= kappa <= fit["parameters"]["kappa"]["ci95"][1], out


def test_an_estimated_x0_is_fitted_and_a_measured_one_held(tmp_path, bundled):
    """The data file's `estimated` key frees x0; without it x0 is held as stated."""
    text = (bundled / "drop_impacts.csv").read_text()
    assert "# estimated" not in text
    estimated = tmp_path / "estimated.csv"
    estimated.write_text(text.replace("# v0 = 0\n", "# v0 = 0\n# estimated = x0\n"))
    d = identify.load_dataset(estimated)
    assert d.estimated == ("x0",) and d.measured == ()
    assert "x0" in identify.fit(estimated, starts=1).free
    assert "x0" not in identify.fit(bundled / "drop_impacts.csv", starts=1).free


@pytest.mark.parametrize("x0", [0.3035, 0.304])
def test_an_inconsistent_fit_never_calls_kappa_identifiable(tmp_path, bundled, x0):
    """The bundled trace with its release height stated 1–1.5 mm low: the fit is
    INCONSISTENT with the stated 0.5 mm noise, and its κ (27 000 N/m in truth) lands near
    10 000–13 000 N/m with a ±2% Gauss–Newton interval. It must not be called identifiable."""
    text = (bundled / "drop_trace.csv").read_text()
    path = tmp_path / "trace.csv"
    path.write_text(text.replace("# x0 = 0.305\n", f"# x0 = {x0}\n"))
    result = identify.fit(path, starts=1)
    assert result.goodness["consistent"] is False
    assert not result.identifiable["kappa"] and not result.identifiable["contact_time"]
    assert not result.identifiable["k_r"]
    assert "inconsistent" in result.withheld["kappa"]
    assert "inconsistent" in result.report()
    assert result.to_json_dict()["withheld"]["kappa"] == result.withheld["kappa"]


def test_a_consistent_fit_keeps_its_kappa_and_the_profile_confirms_it(bundled):
    """The bundled 1 kHz trace (truth κ = 26 660 N/m): identifiable, and the profile that
    confirms it (computed without being asked) holds the truth."""
    result = identify.fit(bundled / "drop_trace.csv", starts=1)
    assert result.identifiable["kappa"] and result.profile is not None
    lo, hi = result.profile.ci95
    assert lo < 26660 < hi


@pytest.mark.parametrize(
    "ci, closes",
    [
        ([2.0e4, 3.0e4], True),
        ([0.0, 3.0e4], False),
        ([2.0e4, float("inf")], False),
        ([float("nan"), 3.0e4], False),
    ],
)
def test_a_profile_open_on_a_side_does_not_close(ci, closes):
    profile = Profile(kappa=np.geomspace(1e3, 1e6, 7), delta_chi2=np.zeros(7), ci95=ci, value=2.5e4)
    assert (profile_closes(profile) is None) is closes
