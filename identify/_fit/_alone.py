"""Each file on its own: the per-file "alone" restitution of a joint fit, and the
joint start points from each file's own solution."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._derived import derived_quantities
from ._joint import Layout
from ._problem import PARAMETERS
from ._robust import Rows
from ._setup import build, start_points
from ._stages import Point, final_pass, lm, row_weights, run_starts, start_restitution, windows_from
from ._uncertainty import covariance


def alone_restitution(setup, best: Point, rows, opts) -> list[dict]:
    """Each file's own restitution when fitted alone (its own κ and k_r).

    One batched LM from the joint optimum over a layout where κ and k_r are per file
    (the drag held at the joint value, the steering prior on each file's t_c): the
    files stay in one compiled call, its runs counted in `setup.evaluator.calls`.
    Returns each file's `{"value", "stderr", "ci95"}`.
    """
    layout = Layout(
        n_files=setup.layout.n_files, shared=("drag",), local=("kappa", "k_r", *setup.layout.local)
    )
    joint_of = [
        int(setup.layout.index[f, PARAMETERS.index(n)]) for n, f in ((n, f or 0) for n, f in layout.names())
    ]
    # What the joint fit frees for a file, file by file (a trace's scale and level only
    # where they apply and are not measured); the drag held.
    free = [j for j, (name, _) in enumerate(layout.names()) if name != "drag" and joint_of[j] in setup.free]
    ev = setup.evaluator.with_(layout=layout, free=free, steps=setup.evaluator.steps[joint_of], prior=True)
    alone = dataclasses.replace(
        setup, layout=layout, evaluator=ev, free=free, lo=setup.lo[joint_of], hi=setup.hi[joint_of]
    )
    z = layout.join(list(setup.layout.split(best.z)))
    point = Point.from_lm(lm(alone, z, row_weights(alone, rows), opts, dchi2=1e-2))
    return [
        derived_quantities(alone, point.z, _alone_covariance(alone, point, rows, f), f=f)["restitution"]
        for f in range(layout.n_files)
    ]


def _alone_covariance(alone, point: Point, rows, f: int) -> np.ndarray:
    """File f's block of the "alone" covariance, from its own rows only.

    The files share nothing in the alone layout (the drag is held), so each file's
    uncertainty comes from its own residual scatter, as a fit of that file alone would
    give it, not from the scatter pooled over every file. The block keeps the file's
    prior row: one drop alone hardly separates t_c from the release height and the
    clock, and e must not inherit that null direction.
    """
    ev = alone.evaluator
    n_data = len(rows.fitted)
    own = np.arange(n_data)[rows.of_file(f)][rows.fitted[rows.of_file(f)]]
    prior = [n_data + k for k, (pf, _, _) in enumerate(ev._prior_pairs()) if pf == f]
    idx = np.concatenate([own, prior]).astype(int)
    entries = set(int(j) for j in alone.layout.index[f])
    cols = [k for k, j in enumerate(ev.free) if j in entries]
    block, _ = covariance(point.jac[np.ix_(idx, cols)], point.r[idx], sigma_known=alone.sigma_known)
    cov = np.zeros((len(ev.free), len(ev.free)))
    cov[np.ix_(cols, cols)] = block
    return cov


#: Joint fits of at most this many files also start from each file's own solution (one
#: alone fit per file: one compilation and a one-start fit each, seconds per file).
MAX_ALONE_STARTS = 4


def alone_starts(setup, opts) -> list[tuple[int, np.ndarray]]:
    """Joint start points from each file fitted alone (one start, no robust pass):
    κ, k_r (and drag) from file f's own optimum, every file's other entries (x0, v0, offset,
    a trace's scale and level) from its own."""
    n = setup.layout.n_files
    if n < 2 or n > MAX_ALONE_STARTS:
        return []
    alone = dataclasses.replace(
        opts, starts=1, method="lm", alone_starts=False, profile=False, progress=False
    )
    own = []
    for d in setup.datasets:
        one = build(
            [d], law=setup.law, nuisance=opts.nuisance, freeze=opts.freeze, initial=setup.initial,
            bounds=opts.bounds, tol=opts.tol,
        )  # fmt: skip
        rows = Rows.make(one.n_rows, opts.holdout)
        e0, _ = start_restitution(one, rows)
        runs = run_starts(one, start_points(one, e0, 1, np.random.default_rng(opts.seed)), rows, alone)
        point = final_pass(one, windows_from(one, runs[0], rows, alone), rows, alone)
        setup.evaluator.counter.n += one.evaluator.calls
        own.append(np.asarray(point.z) if math.isfinite(point.cost) else None)
    if any(z is None for z in own):
        return []
    out = []
    for f in range(n):
        z = setup.layout.join(own)
        shared = [PARAMETERS.index(name) for name in setup.layout.shared]
        z[setup.layout.index[0, shared]] = own[f][shared]
        out.append((f, np.clip(z, setup.lo, setup.hi)))
    return out
