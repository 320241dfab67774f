"""Honest uncertainty for impact onsets, against throws made in closed form (`throws.py`,
which shares nothing with jaxunilat or identify).

- Coverage: the nominal 95% interval of e covers the truth in at least 90% of 40 throws
  with 0.2-0.5% bounce-to-bounce scatter of e, over a spread of balls (e 0.75-0.95,
  drops 0.3-0.9 m, drag 0.005-0.1 s/m), fitted with the defaults.
- A throw's interval alone is consistent with the same throw's "e alone" in a joint fit.
- The closed-form gate: a fit that contradicts the data's own flight ratios or release
  height is not converged, identifies nothing, and the command line exits 3.
"""

import dataclasses
import json

import numpy as np
import pytest
from jaxunilat.identify._fit._plausible import closed_form, contradictions
from throws import throw

from jaxunilat import identify

MASS = 0.04


def _dataset(seed: int, *, e: float, scatter: float, h0: float, drag: float, bounces: int, name: str = ""):
    t, _ = throw(seed, e=e, scatter=scatter, h0=h0, drag=drag, bounces=bounces)
    return identify.Dataset(
        scene="drop", observe="impacts", mass=MASS, drag=drag, x0=h0, v0=0.0, t=t, path=name or None
    )


def _ball(seed: int) -> dict:
    """A ball and drop drawn for `seed`: e, scatter, height, drag (10 bounces: one compiled
    structure for every throw)."""
    rng = np.random.default_rng(1000 + seed)
    return dict(
        e=float(rng.uniform(0.75, 0.95)),
        scatter=float(rng.uniform(0.002, 0.005)),
        h0=float(rng.uniform(0.3, 0.9)),
        drag=float(rng.uniform(0.005, 0.1)),
        bounces=10,
    )


@pytest.mark.slow
@pytest.mark.parametrize("chunk", range(4))
def test_the_95_percent_interval_of_e_covers_the_truth(chunk):
    """10 throws per chunk, 40 in all: at least 9 of each 10 covered (>= 90% overall)."""
    missed = []
    for seed in range(10 * chunk, 10 * chunk + 10):
        ball = _ball(seed)
        result = identify.fit(_dataset(seed, **ball), starts=1)
        e = result.derived["restitution"]
        lo, hi = e.ci95
        assert result.converged and not result.contradictions, (seed, ball, result.message)
        assert 0 < hi - lo < 0.1, (seed, ball, e)  # bounded, and neither zero-width nor vacuous
        if not lo <= ball["e"] <= hi:
            missed.append((seed, round(ball["e"], 4), round(e.value, 4), (round(lo, 4), round(hi, 4))))
    assert len(missed) <= 1, f"the 95% interval missed the truth in {len(missed)} of 10 throws: {missed}"


def test_a_throws_interval_matches_its_e_alone_in_a_joint_fit():
    """The same throw fitted alone and inside a joint fit of three throws of one ball: the
    two intervals of its e agree (within a factor 1.6 in width, the values within them)."""
    files = [
        _dataset(seed, e=0.88, scatter=0.004, h0=h0, drag=0.04, bounces=10, name=f"throw{seed}.csv")
        for seed, h0 in ((1, 0.4), (2, 0.5), (3, 0.6))
    ]
    joint = identify.fit(files, starts=1)
    for f, data in enumerate(files):
        single = identify.fit(data, starts=1).derived["restitution"]
        alone = joint.datasets[f].restitution_alone
        ratio = single.stderr / alone.stderr
        assert 1 / 1.6 < ratio < 1.6, (data.path, single, alone)
        assert abs(single.value - alone.value) < 0.5 * (single.stderr + alone.stderr)


def test_the_gate_flags_an_e_the_flight_ratios_contradict():
    """A result whose e sits far from the data's closed form (as a wrong basin does) is
    flagged, naming the file and both numbers; the true e is not."""
    data = _dataset(7, e=0.76, scatter=0.003, h0=0.65, drag=0.046, bounces=6, name="tennis.csv")
    form = closed_form(data)
    assert abs(form.restitution - 0.76) < 0.01  # the closed form itself, against the truth
    result = identify.fit(data, starts=1)
    assert result.converged and result.contradictions == ()
    wrong = dataclasses.replace(result.derived["restitution"], value=0.0055)  # what a wrong basin reported
    result = dataclasses.replace(result, derived={**result.derived, "restitution": wrong})
    found = contradictions(result)
    assert len(found) == 1 and "tennis.csv" in found[0] and "0.0055" in found[0]
    assert f"{form.restitution:.4f}" in found[0]


def test_a_release_height_the_first_flight_contradicts_exits_3(tmp_path, capsys):
    """A drop recorded from its second bounce on, with the release height stated: the first
    flight cannot follow from that height; identify says so and exits 3, identifying nothing."""
    from jaxunilat._cli._main import main

    t, _ = throw(3, e=0.9, scatter=0.003, h0=0.8, drag=0.029, bounces=12)
    data = identify.Dataset(scene="drop", observe="impacts", mass=0.0415, drag=0.029, x0=0.8, v0=0.0, t=t[1:])
    path = tmp_path / "late.csv"
    identify.write_dataset(path, data)
    code = main(["--no-cache", "identify", str(path), "--json", str(tmp_path / "fit.json"), "--starts", "1"])
    out = capsys.readouterr().out
    assert code == 3, out
    assert "cannot follow a drop from the stated x0 = 0.8 m" in out and "later bounce" in out
    doc = json.loads((tmp_path / "fit.json").read_text())
    assert doc["converged"] is False and not any(doc["identifiable"].values())
