"""A joint fit of files of one structure compiles its residual program once per contact law.

The files are closed-form quadratic-drag drops (`identify._bench.throws`, the bench's
joint-fit workload; no jaxunilat run makes them). The count is the jitted entry point's own cache
(`identify._fit._problem.evaluate_rows`): one compiled program per law, whatever the number
of files, starts, windows and passes; files of the same structure fitted later reuse it.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from jaxunilat.identify._bench import throws
from jaxunilat.identify._fit._alone import MAX_ALONE_STARTS
from jaxunilat.identify._fit._problem import evaluate_rows

from jaxunilat import identify

#: Few bounces and a unique row count: the programs compiled here are this test's own.
BOUNCES = 7
#: More files than `MAX_ALONE_STARTS` (each file's own start compiles a one-file program).
FILES = MAX_ALONE_STARTS + 1


def _files(seed: int) -> list:
    return throws(FILES, seed, bounces=BOUNCES)


def test_a_joint_fit_compiles_once_per_law_and_auto_reuses_the_programs():
    before = evaluate_rows._cache_size()
    auto = identify.fit(_files(1), law="auto", starts=1)
    compiled = evaluate_rows._cache_size() - before
    assert compiled <= 2, (
        f"law='auto' on {FILES} files compiled {compiled} residual programs; expected one per law"
    )
    assert auto.simulations > 10 * compiled  # many calls of those programs

    # Each law alone, on these files and on others of the same structure: nothing compiles again.
    again = evaluate_rows._cache_size()
    alone = {law: identify.fit(_files(1), law=law, starts=1) for law in ("kelvin-voigt", "hunt-crossley")}
    identify.fit(_files(2), law="kelvin-voigt", starts=1)
    assert evaluate_rows._cache_size() == again

    # The laws fitted side by side give what each gives alone, the files' "alone" e too.
    assert abs(auto.laws["kelvin-voigt"]["restitution"] - 0.9) < 0.01  # the throws' closed-form e
    for law, single in alone.items():
        mine = auto.laws[law]
        assert np.isclose(mine["chi2"], single.laws[law]["chi2"], rtol=1e-9)
        for name in ("kappa", "k_r"):
            assert np.isclose(mine["parameters"][name], single.params[name].value, rtol=1e-9)
    chosen = alone[auto.law]
    assert auto.simulations == chosen.simulations
    for mine, single in zip(auto.datasets, chosen.datasets, strict=True):
        assert np.isclose(mine.restitution_alone.value, single.restitution_alone.value, rtol=1e-9)


def test_bench_fits_only_jaxunilat_data_files():
    """The bench's identification row fits the bundled `jaxunilat-data` files, never a raw
    phyphox export (which `identify.fit` refuses: it needs `jaxunilat import` first)."""
    from jaxunilat.identify._bench import fit_sets

    from jaxunilat._internal import bundled_data

    paths = bundled_data("*.csv")
    if not paths:
        pytest.skip("the bundled data/ folder is not present")
    chosen = {os.path.basename(p) for p in fit_sets(paths)}
    assert "drop_trace.csv" in chosen
    assert not any(name.startswith("phyphox_") for name in chosen)
    for path in fit_sets(paths):
        identify.load_dataset(path)  # each one reads
