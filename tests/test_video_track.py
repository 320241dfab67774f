"""The video tracker's two choices from candidate blobs, on positions written down here: the
gravity vote (`gravity_votes`) and the path through the frames (`choose_path`).

The references are the parabolas the positions were made from (g in px/s², the frame
times), never the tracker's output.
"""

from __future__ import annotations

import numpy as np
from jaxunilat.identify._data._video_track import _Candidates, choose_path, gravity_votes

STEP = 0.04  # s, 25 frames/s
G = 5000.0  # px/s^2, the ball's fall in the picture


def _blobs(points, areas) -> _Candidates:
    """The candidates of one frame: centroids (px) and areas (px), nothing shadow-like."""
    pos = np.asarray(points, dtype=float).reshape(-1, 2)
    area = np.asarray(areas, dtype=float)
    n = len(pos)
    return _Candidates(pos, area, area * 50.0, np.full((n, 3), 200.0), np.zeros(n))


def _fall(t, g, t_apex, y_apex):
    """Image y (px, down) of a body whose apex is at (t_apex, y_apex), falling at g px/s²."""
    return y_apex + 0.5 * g * (np.asarray(t) - t_apex) ** 2


def test_unlike_blobs_that_line_up_on_a_parabola_do_not_vote():
    """Seven frames of the ball (three five-frame chains) at G; then eight frames in which a
    codec's 4 px speck, the floor's contact shadow and the 500 px ball take turns on a
    parabola of 3 G (four chains). Three things of areas 150 times apart are no falling
    ball: the vote is G (within the 5 % bins), as it is for the ball alone."""
    t = np.arange(15) * STEP
    ball = _fall(t[:7], G, t[3] + 0.02, 100.0)
    cands = [_blobs([(160.0, y)], [500.0]) for y in ball]
    fake = _fall(t[7:], 3 * G, t[10] + 0.02, 60.0)
    areas = [4.0, 120.0, 500.0]
    cands += [_blobs([(150.0, y)], [areas[k % 3]]) for k, y in enumerate(fake)]
    g = gravity_votes(cands, t, reach=100.0)
    assert abs(g / G - 1) < 0.05, g
    alone = gravity_votes(cands[:7], t[:7], reach=100.0)
    assert abs(alone / G - 1) < 0.05, alone


def test_path_keeps_the_ball_at_an_apex_between_dropped_frames_with_g_misjudged():
    """The ball at G over an apex whose frames on either side are missing (one dropped from
    the file, one a near-still apex frame taken for a repeat: the steps double), the path
    given a g 17 % low (the vote's uncertainty under a rolling shutter): the ball is chosen
    in every frame. Over a doubled step the fall is four times larger, and so is the miss
    of a misjudged g, while an apex's slow motion leaves little tolerance for speed."""
    t = np.r_[np.arange(6), 7, 9, 10, 11, 12] * STEP
    y = _fall(t, G, t[6], 100.0)
    pos = np.stack([np.full(len(t), 160.0), y], axis=1)[:, None, :]
    pos = np.concatenate([pos, np.full((len(t), 1, 2), np.nan)], axis=1)  # slot 1: none
    cost = np.zeros((len(t), 2))
    cost[:, 1] = 4.0  # the tracker's cost of choosing nothing in a frame
    path = choose_path(pos, cost, t, 0.83 * G, limit=100.0, known=True)
    assert np.all(path == 0), path
