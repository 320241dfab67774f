"""The numerical stress suite: every run is accurate to its contract or a clear error.

`pytest -m stress` runs all configurations from `stress_configs.make_configs()` (500 by
default, `JAXUNILAT_STRESS_N` to change); the default run checks a quick subset that
shares one compiled structure per mode. Both write the summary table (configurations,
passes, clear errors, silent failures) to `JAXUNILAT_STRESS_TABLE` if set, else under
pytest's tmp_path, and print it. The accuracy contract is in `stress_configs`'s docstring
and in jaxunilat/README.md.
"""

import json
import math
import os

import numpy as np
import pytest
from reference import BallParams, closed_form_reference, scipy_reference
from stress_configs import GRAVITY, MASS, MODES, make_configs, run_all, summary_table


def _write(outcomes, tmp_path, name):
    table = summary_table(outcomes)
    path = os.environ.get("JAXUNILAT_STRESS_TABLE") or str(tmp_path / name)
    with open(path, "w") as fh:
        fh.write(table + "\n")
    rows = [
        dict(
            index=o.config.index,
            mode=o.config.mode,
            family=o.config.family,
            kappa=o.config.kappa,
            k_r=o.config.k_r,
            drag=o.config.drag,
            two_sided=o.config.upper is not None,
            t1=o.config.t1,
            kind=o.kind,
            error=o.error,
            bound=o.bound,
            detail=o.detail,
            seconds=o.seconds,
        )
        for o in outcomes
    ]
    with open(os.path.splitext(path)[0] + ".json", "w") as fh:
        json.dump(rows, fh, indent=1)
    print(f"\nstress summary ({path}):\n{table}")
    return table


def _silent(outcomes):
    return [
        f"#{o.config.index} {o.config.mode} {o.config.family} kappa={o.config.kappa:.3g} t1={o.config.t1:.3g}: "
        f"err {o.error:.3g} > bound {o.bound:.3g} ({o.detail})"
        for o in outcomes
        if o.kind == "silent"
    ]


def _quick_configs():
    """Two-sided walls with drag, κ ≤ 3e5 N/m, t1 ≤ 1 s, any damping: two compiles (event,
    tsit5) and references that take well under a second each (the dropped-to-rest family is
    one-sided, a third and fourth compile: `test_reference_settles_like_the_closed_form`
    checks the reference's resting contact instead)."""
    picked, per_mode = [], dict.fromkeys(MODES, 0)
    for c in make_configs(4000):  # the full suite's 500 first, then more from the same seed
        if c.upper is None or c.drag is None or c.t1 > 1.0 or c.kappa > 3e5:
            continue
        if c.mode not in ("event", "tsit5", "float32-inputs", "float32") or per_mode[c.mode] >= 4:
            continue
        per_mode[c.mode] += 1
        picked.append(c)
    return picked


def test_stress_quick_subset(tmp_path):
    configs = _quick_configs()
    assert len(configs) >= 12
    outcomes = run_all(configs)
    _write(outcomes, tmp_path, "stress_quick.md")
    assert not _silent(outcomes), "\n".join(_silent(outcomes))
    # The subset must exercise the contract, not only clear errors, and judge every run.
    assert sum(o.kind == "pass" for o in outcomes) >= len(configs) // 2
    assert not any(o.kind == "unjudged" for o in outcomes)
    assert any(o.kind == "clear" and o.config.mode == "float32" for o in outcomes)


def _quick_rest_configs(per_kind=3):
    """Event mode (Tsit5 and Dopri8 pieces) with drag: balls dropped to rest on one wall,
    grazing apexes at the upper wall and horizons of 5 s or more, `per_kind` of each from
    the same seed, any κ. Damping ζ ≥ 0.1, so that the balls settle within the horizon and
    the references (which detect the rest) take well under a second; four compiles
    (two modes, one- and two-sided walls)."""
    picked, count = [], {}
    for c in make_configs(4000):
        if c.mode not in ("event", "event-dopri8") or c.drag is None:
            continue
        if c.k_r < 0.1 * 2 * math.sqrt(c.kappa * MASS):
            continue
        kind = c.family if c.family in ("rest", "grazing") else ("long" if c.t1 >= 5.0 else None)
        if kind is None or count.get((c.mode, kind), 0) >= per_kind:
            continue
        count[(c.mode, kind)] = count.get((c.mode, kind), 0) + 1
        picked.append(c)
    return picked


def test_stress_quick_rest_subset(tmp_path):
    """Balls that come to rest (or bounce for long) never run out of steps: every run of
    the subset succeeds within its contract, none is even a clear error."""
    configs = _quick_rest_configs()
    assert len(configs) == 18
    outcomes = run_all(configs)
    _write(outcomes, tmp_path, "stress_quick_rest.md")
    assert not _silent(outcomes), "\n".join(_silent(outcomes))
    failed = [f"#{o.config.index} {o.config.mode} {o.config.family}: {o.kind} ({o.detail})" for o in outcomes]
    failed = [line for line, o in zip(failed, outcomes, strict=True) if o.kind != "pass"]
    assert not failed, "\n".join(failed)


@pytest.mark.stress
def test_stress_full(tmp_path, request):
    configs = make_configs(int(os.environ.get("JAXUNILAT_STRESS_N", "500")))
    outcomes = run_all(configs)
    _write(outcomes, tmp_path, "stress_full.md")
    assert not _silent(outcomes), "\n".join(_silent(outcomes))


@pytest.mark.parametrize(
    ("kappa", "zeta", "drop"), [(7.045e6, 0.43, 2.2e-3), (2e5, 0.02, 0.02), (1e9, 0.3, 0.01)]
)
def test_reference_settles_like_the_closed_form(kappa, zeta, drop):
    """A ball dropped onto the lower wall bounces, then rests in a contact that cannot end:
    the scipy reference (rest detection, held rest state) against the drag-free closed form
    (its own exit search by a scan + brentq), and the rest at x = wall − mg/κ."""
    p = BallParams(kappa=kappa, k_r=zeta * 2 * math.sqrt(kappa * MASS), drag=None, lower=-0.4, upper=None)
    t1 = 3.0
    ref = scipy_reference(p, (-0.4 + drop, 0.0), t1, max_seconds=30)
    exact = closed_form_reference(p, (-0.4 + drop, 0.0), t1, max_segments=20_000)
    ts = np.linspace(0.0, t1, 20001)
    (x, _), (xe, _) = ref(ts), exact(ts)
    assert np.max(np.abs(x - xe)) <= 1e-12
    assert len(ref.contacts) == len(exact.contacts) >= 2
    assert math.isnan(ref.contacts[-1].t_out)  # the last contact never ends
    assert x[-1] == pytest.approx(-0.4 - MASS * GRAVITY / kappa, abs=1e-13)
