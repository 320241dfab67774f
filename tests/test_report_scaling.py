"""Fit reports that stay readable with 1, 5 and 30 files: the per-file table (text and
JSON), units on every residual, readable bounds for unidentifiable parameters, and a
`plot_fit` whose legends never cover the data.

Two small real fits (scipy-reference onsets of a 2.7 g ball, κ = 1.6e4 N/m,
k_r = 0.15 N·s/m, drag 0.12 s/m, `starts=1`): one file, and two files (one with a
spurious click, one with a bounce unheard). The 5- and 30-file results are the two-file
fit's files repeated under new names and heights (`_tiled`): what is tested here is the
layout of the report and the figure, not the fit.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
from jaxunilat.identify._fit._joint import Layout
from reference import BallParams, scipy_reference

from jaxunilat import identify

KAPPA, K_R, MASS, DRAG, NOISE = 1.6e4, 0.15, 2.7e-3, 0.12, 2e-5
FILE_FIELDS = {"name", "rows", "x0", "v0", "offset", "e_alone", "rms", "outliers", "held_out"}
#: The keys `to_json_dict` had before the per-file table: kept as they are.
OLD_KEYS = {
    "parameters", "derived", "identifiable", "correlation", "converged", "nuisance", "fitted",
    "correlation_all", "mass", "scene", "observe", "data", "n_data", "chi2", "sigma", "sigma_source",
    "goodness_of_fit", "message", "method", "iterations", "rel_halfwidth", "wall_s", "law", "law_choice",
    "units", "laws", "noise", "robust", "outliers", "datasets", "holdout", "notes", "profile_kappa",
}  # fmt: skip


def _onsets(x0: float, n: int) -> np.ndarray:
    params = BallParams(kappa=KAPPA, k_r=K_R, mass=MASS, drag=DRAG, lower=0.0, upper=None)
    return scipy_reference(params, (x0, 0.0), 6.0, rtol=1e-10, atol=1e-12).impact_times()[:n]


def _impacts(t, x0, path):
    return identify.Dataset(
        scene="drop", observe="impacts", mass=MASS, drag=DRAG, x0=x0, v0=0.0, noise=NOISE, t=t, path=path
    )


@pytest.fixture(scope="module")
def one():
    t = _onsets(0.30, 9) + 0.03 + np.random.default_rng(1).normal(0.0, NOISE, 9)
    return identify.fit(_impacts(t, 0.30, "/data/drop_300mm.csv"), nuisance=("offset",), starts=1)


@pytest.fixture(scope="module")
def two():
    rng = np.random.default_rng(2)
    a = _onsets(0.20, 10) + 0.05 + rng.normal(0.0, NOISE, 10)
    a = np.sort(np.append(a, a[3] + 0.5 * (a[4] - a[3]) + 0.013))  # a spurious click
    b = np.delete(_onsets(0.30, 11) + 0.02 + rng.normal(0.0, NOISE, 11), 6)  # bounce 6 unheard
    files = [_impacts(a, 0.20, "/data/drop_200mm.csv"), _impacts(b, 0.30, "/data/drop_300mm.csv")]
    return identify.fit(files, nuisance=("offset",), starts=1, holdout=0.1)


def _tiled(result, n: int):
    """An n-file result from `result`'s files, repeated under new names and heights."""
    k = len(result.datasets_data)
    pick = [f % k for f in range(n)]
    starts = np.cumsum([0] + [d.num_rows for d in result.datasets_data])
    rows = [np.arange(starts[f], starts[f + 1]) for f in range(k)]
    data = [
        dataclasses.replace(result.datasets_data[g], path=f"/data/throw_{f:02d}.csv", x0=0.1 + 0.01 * f)
        for f, g in enumerate(pick)
    ]
    entries = [dataclasses.replace(result.datasets[g], data=data[f].path) for f, g in enumerate(pick)]
    old, new = Layout(k), Layout(n)
    z = np.asarray(result.joint_z)
    joint = new.join([z[old.index[g]] for g in pick])
    joint[new.index[:, 3]] = [d.x0 for d in data]  # the release heights, held
    index = np.concatenate([rows[g] for g in pick])
    return dataclasses.replace(
        result,
        datasets=entries,
        datasets_data=data,
        residuals=np.asarray(result.residuals)[index],
        used=np.asarray(result.used)[index],
        row_sigma=np.asarray(result.row_sigma)[index],
        joint_z=joint,
    )


@pytest.fixture(scope="module")
def results(one, two):
    """The results at 1, 2, 5 and 30 files."""
    return {1: one, 2: two, 5: _tiled(two, 5), 30: _tiled(two, 30)}


@pytest.mark.parametrize("n", [1, 2, 5, 30])
def test_json_files_table_has_one_entry_per_file(results, n):
    result = results[n]
    doc = json.loads(json.dumps(result.to_json_dict(), allow_nan=False))
    assert set(doc) >= OLD_KEYS  # extended, nothing renamed
    files = doc["files"]
    assert len(files) == n
    names = [f["name"] for f in files]
    assert len(set(names)) == n
    for f, entry in zip(files, result.datasets, strict=True):
        assert set(f) >= FILE_FIELDS
        assert f["rows"] == entry.rows and f["outliers"] == len(entry.outliers)
        assert f["held_out"] == entry.held_out
        for name in ("x0", "offset"):
            assert set(f[name]) >= {"value", "stderr", "unit", "status"}
        assert f["offset"]["status"] == "fitted" and f["offset"]["stderr"] > 0 and f["offset"]["unit"] == "s"
        assert f["x0"]["status"] == "fixed" and f["x0"]["stderr"] is None and f["x0"]["unit"] == "m"
        assert f["offset"]["value"] == pytest.approx(entry.params["offset"].value)
        assert 0.9 < f["e_alone"]["value"] < 1.0 and f["e_alone"]["stderr"] > 0
        assert f["rms"]["unit"] == "s" and 0 < f["rms"]["value"] < 1e-3
    assert sum(f["outliers"] for f in files) == sum(len(e.outliers) for e in result.datasets)


def _section(report: str, name: str) -> list[str]:
    lines = report.splitlines()
    start = lines.index(next(line for line in lines if line.startswith(f"[[{name}]]")))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[[")), len(lines))
    return lines[start:end]


@pytest.mark.parametrize("n", [2, 5, 30])
def test_report_names_the_file_for_per_file_values(results, n):
    result = results[n]
    report = result.report()
    nuisance = _section(report, "Nuisance parameters")
    # No bare per-file value among the nuisance parameters: they point to the per-file table.
    assert not any(re.match(r"\s+(x0|v0|offset)\s*=", line) for line in nuisance)
    assert any("offset fitted per file" in line and "[[Files]]" in line for line in nuisance)
    table = _section(report, "Files")
    assert "offset (ms)" in table[1] and "e alone" in table[1]
    for f in result.file_table():
        row = next(line for line in table[2:] if line.split()[0] == f["name"])
        shown = [float(v) for v in re.findall(r"([-\d.]+) \+/- [\d.]+", row)]
        assert any(abs(v - f["offset"]["value"] * 1e3) < 0.01 for v in shown), row  # its offset, ms


def test_one_file_report_keeps_its_variables(one):
    nuisance = _section(one.report(), "Nuisance parameters")
    assert any(re.match(r"\s+offset\s*=", line) for line in nuisance)
    assert "(shared by every file)" not in nuisance[0]


@pytest.mark.parametrize("n", [1, 2, 30])
def test_every_printed_residual_has_a_unit(results, n):
    report = results[n].report()
    residual_lines = [line for line in report.splitlines() if "residual" in line and "outlier:" in line]
    assert len(residual_lines) == sum(len(e.outliers) for e in results[n].datasets)
    for line in residual_lines:
        assert re.search(r"residual [-+]?[\d.]+(e[-+]?\d+)? (ms|mm)\b", line), line
    for line in (line for line in report.splitlines() if "missed bounce" in line):
        assert re.search(r"interval [\d.]+ ms after one of [\d.]+ ms", line), line
    table = _section(report, "Files" if n > 1 else "Rows")
    assert "rms (ms)" in table[1]
    if n == 2:
        assert len(residual_lines) == 1 and "missed bounce" in report


def _absurd_numbers(text: str) -> list[str]:
    """Numbers printed as 1e+30 or beyond, or 1e-30 or below."""
    return [m.group(0) for m in re.finditer(r"\d(\.\d+)?e([-+]?\d+)", text) if abs(int(m.group(2))) >= 30]


def test_unidentifiable_parameters_print_what_the_data_bound(one):
    kappa = dataclasses.replace(
        one.params["kappa"], stderr=3.4e6, ci95=(1.9e-130, 3.8e138), identifiable=False
    )
    t_c = dataclasses.replace(
        one.derived["contact_time"], value=2e-5, stderr=3e-4, ci95=(1e-9, 3e-3), identifiable=False
    )
    result = dataclasses.replace(
        one, params={**one.params, "kappa": kappa}, derived={**one.derived, "contact_time": t_c}
    )
    report = result.report()
    assert _absurd_numbers(report) == []
    kappa_line = next(line for line in _section(report, "Results") if line.strip().startswith("kappa"))
    assert "not bounded by the data" in kappa_line and "identifiable: NO" in kappa_line
    t_c_line = next(line for line in _section(report, "Results") if line.strip().startswith("t_c"))
    assert "t_c < 3 ms" in t_c_line and "identifiable: NO" in t_c_line
    doc = json.loads(json.dumps(result.to_json_dict(), allow_nan=False))
    assert doc["parameters"]["kappa"]["ci95"] == [1.9e-130, 3.8e138]  # the numbers stay
    assert doc["bounds"]["kappa"]["kind"] == "none" and doc["bounds"]["kappa"]["lower"] is None
    assert "not bounded by the data" in doc["bounds"]["kappa"]["text"]
    assert doc["bounds"]["contact_time"] == {
        "kind": "upper", "lower": None, "upper": 3e-3, "unit": "s",
        "text": "t_c < 3 ms (95%; no lower bound from the data)",
    }  # fmt: skip
    assert doc["bounds"]["restitution"]["kind"] == "interval"


@pytest.mark.parametrize(
    ("name", "value", "ci95", "kind"),
    [
        ("kappa", 2e4, [1.4e4, 2.9e4], "interval"),
        ("kappa", 2.7e4, [210.0, 3.4e6], "none"),  # 4.2 decades
        ("kappa", 2e4, [-math.inf, math.inf], "none"),
        ("kappa", 2e4, [0.0, 5e4], "upper"),  # a profile likelihood open below
        ("kappa", 2e4, [1e4, math.nan], "lower"),
        ("k_r", 0.15, [1e-40, 1e38], "none"),
        ("contact_time", 1e-3, [1e-4, 1e-2], "interval"),
        ("restitution", 0.5, [0.0, 1.0], "none"),
        ("restitution", 0.999, [0.997, 1.0], "interval"),
    ],
)
def test_bound_rule(name, value, ci95, kind):
    from jaxunilat.identify._fit._estimate import Estimate, bound

    b = bound(name, value, ci95)
    assert b.kind == kind
    assert _absurd_numbers(b.text) == []
    if kind == "none":
        assert b.text.startswith("not bounded by the data")
    assert Estimate(name, value, 1.0, ci95).bound == b  # an estimate's bound is the same rule


def _overlap(a, b) -> float:
    """Area (px²) shared by two display-space boxes."""
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return max(w, 0.0) * max(h, 0.0)


@pytest.mark.parametrize("n", [1, 5, 30])
def test_plot_fit_keeps_legends_off_the_data_and_panels_tall(results, n):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = identify.plot.plot_fit(results[n])
    FigureCanvasAgg(fig)
    fig.canvas.draw()
    data_axes = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(data_axes) == 2
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    for legend in legends:
        box = legend.get_window_extent()
        for ax in data_axes:
            assert _overlap(box, ax.get_window_extent()) < 1.0
    for ax in data_axes:
        box = ax.get_window_extent()
        assert box.height >= 250 and box.width >= 300, (box.width, box.height)
        assert re.search(r"\[.+\]", ax.get_xlabel()) and re.search(r"\[.+\]", ax.get_ylabel())  # units
    width, height = fig.get_size_inches()
    assert width <= 16 and height <= 10
    # Held-out rows are open circles, outliers red crosses (or triangles at the edge).
    residuals = data_axes[1]
    held = [ln for ln in residuals.lines if ln.get_marker() == "o" and ln.get_markerfacecolor() == "none"]
    outliers = [ln for ln in residuals.lines if ln.get_marker() in ("x", "^", "v") and ln.get_color() == "C3"]
    assert bool(held) == (n > 1) and bool(outliers) == (n > 1)
    # Beyond MANY_FILES, a colour bar stands for the legend of file names.
    assert (len(fig.axes) == 3) == (n > identify._report._plot.MANY_FILES)
