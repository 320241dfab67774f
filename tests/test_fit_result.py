"""The fit's result: frozen and typed, built once by the fit layer, with `Estimate`s
(`result.params["kappa"].value`); its JSON keeps its keys through a round trip; and the
report modules only format (they import no solver and no fit computation of `_fit`).
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import json
import os
import pathlib

import numpy as np
import pytest
from jaxunilat.identify._fit._estimate import Bound

import jaxunilat
from jaxunilat import identify

DATA = os.path.join(os.path.dirname(__file__), os.pardir, "data")
REPORT = pathlib.Path(identify.__file__).parent / "_report"

#: The top-level keys of `to_json_dict`, in order.
JSON_KEYS = [
    "parameters", "derived", "identifiable", "withheld", "correlation", "converged", "nuisance", "fitted",
    "correlation_all", "mass", "scene", "observe", "data", "n_data", "chi2", "sigma", "sigma_source",
    "goodness_of_fit", "message", "method", "iterations", "rel_halfwidth", "wall_s", "law", "law_choice",
    "units", "laws", "noise", "robust", "outliers", "datasets", "holdout", "notes", "restitution_trend",
    "restart", "files", "bounds", "profile_kappa",
]  # fmt: skip
#: The keys of each entry of the JSON's `datasets`, in order.
FILE_KEYS = [
    "data", "observe", "rows", "used", "held_out", "outliers", "missed", "rms", "sigma", "parameters",
    "restitution_alone",
]  # fmt: skip


@pytest.fixture(scope="module")
def result():
    """A real fit of the bundled rebound apex heights (one start: quick)."""
    return identify.fit(os.path.join(DATA, "drop_apex.csv"), starts=1)


def test_the_result_is_frozen(result):
    assert isinstance(result, identify.FitResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.converged = False
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.params["kappa"].value = 1.0
    with pytest.raises(TypeError):
        result.params["kappa"] = result.params["k_r"]
    with pytest.raises(TypeError):
        result.identifiable["kappa"] = True
    with pytest.raises(ValueError, match="read-only"):
        result.residuals[0] = 0.0
    assert isinstance(result.notes, tuple) and isinstance(result.datasets, tuple)
    assert isinstance(result.contradictions, tuple) and isinstance(result.free, tuple)
    # A variant is a new result; the original stays as it was.
    other = dataclasses.replace(result, notes=(*result.notes, "a note"))
    assert other.notes[-1] == "a note" and "a note" not in result.notes


def test_parameters_are_estimates_with_units(result):
    kappa = result.params["kappa"]
    assert isinstance(kappa, identify.Estimate) and kappa.name == "kappa"
    assert kappa.unit == "N/m" and result.params["k_r"].unit == "N*s/m"
    assert result.derived["contact_time"].unit == "s" and result.derived["restitution"].unit == ""
    assert result.params["x0"].unit == "m" and result.params["v0"].unit == "m/s"
    assert kappa.value == result.kappa and not kappa.fixed
    lo, hi = kappa.ci95
    assert lo <= kappa.value <= hi and kappa.stderr > 0
    # The held drag: fixed, no standard error, a point interval.
    drag = result.params["drag"]
    assert drag.fixed and drag.stderr == 0.0 and drag.ci95 == (drag.value, drag.value)
    # Verdicts: on κ, k_r, e and t_c only, and `identifiable` is their view.
    assert result.identifiable == {name: result.estimate(name).identifiable for name in result.identifiable}
    assert result.params["x0"].identifiable is None
    assert result.identifiable["restitution"] and not result.identifiable["kappa"]  # apex heights: e only
    # What the data bound: a `Bound` for κ, k_r, drag, e, t_c; none for the release state.
    assert isinstance(kappa.bound, Bound) and kappa.bound.kind == "none"
    assert result.derived["restitution"].bound.kind == "interval"
    assert result.params["x0"].bound is None


def test_the_json_round_trip_keeps_the_keys(result):
    doc = result.to_json_dict()
    again = json.loads(json.dumps(doc, allow_nan=False))
    assert list(again) == JSON_KEYS
    assert again == json.loads(json.dumps(doc, allow_nan=False))
    assert list(again["parameters"]) == ["kappa", "k_r"]
    assert list(again["derived"]) == ["restitution", "contact_time"]
    assert again["parameters"]["kappa"] == json.loads(json.dumps(result.params["kappa"].to_json()))
    assert list(again["parameters"]["kappa"]) == ["value", "stderr", "ci95"]
    assert [list(d) for d in again["datasets"]] == [FILE_KEYS]
    assert list(again["bounds"]["kappa"]) == ["kind", "lower", "upper", "unit", "text"]
    assert again["units"] == {"kappa": "N/m", "k_r": "N*s/m"}


def test_the_contact_laws_say_whether_their_e_depends_on_the_speed():
    assert not jaxunilat.KelvinVoigt().restitution_depends_on_speed
    assert not jaxunilat.ClampedKelvinVoigt().restitution_depends_on_speed
    assert jaxunilat.HuntCrossley(1.5).restitution_depends_on_speed


#: Modules whose import means solving or fitting, which the report never needs.
SOLVERS = ("jax", "optax", "scipy.optimize", "diffrax", "jaxunilat")


def _imports(path: pathlib.Path):
    """(module, names) of every import in `path` (inside functions too), relative ones
    resolved against identify's report package."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                package = ["jaxunilat", "identify", "_report"][: 3 - (node.level - 1)]
                base = ".".join([*package, *([base] if base else [])])
            yield base, tuple(alias.name for alias in node.names)


def test_the_report_imports_no_solver_and_no_fit_computation():
    """`identify/_report` formats text, JSON and figures: it imports no solver (jax, optax,
    jaxunilat's simulator), and from the fit layer only types and constants, never a
    function that computes (a covariance, a refit, a simulation, the gate)."""
    found = []
    for path in sorted(REPORT.glob("*.py")):
        for module, names in _imports(path):
            if module.split(".")[0] in SOLVERS and not module.startswith("jaxunilat._internal"):
                if not module.startswith("jaxunilat.identify"):
                    found.append(f"{path.name}: import {module}")
            if module.startswith("jaxunilat.identify._fit"):
                loaded = importlib.import_module(module)
                for name in names:
                    value = getattr(loaded, name)
                    if callable(value) and not isinstance(value, type):
                        found.append(f"{path.name}: {module}.{name} computes")
    assert found == []


def test_the_fit_layer_builds_what_the_report_shows(result):
    """Each number the report prints comes with the result: the report of a result
    rebuilt from its own fields reads the same (nothing is recomputed when formatting)."""
    fields = {f.name: getattr(result, f.name) for f in dataclasses.fields(result)}
    again = identify.FitResult(**fields)
    assert again.report() == result.report()
    assert np.array_equal(again.residuals, result.residuals)
