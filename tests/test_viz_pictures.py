"""The pictures `avp demo` writes (avp_viz.render, avp_viz.episode_video): with several egos every ego is drawn in
its own colour and named in the legend, and a legend too long for the picture wraps rather than being cut."""

from __future__ import annotations

import math

import cv2
import numpy as np

from avp_viz.render import EGO, EGO_BGR, legend_band, render_episode

ENTRIES = [("b=0", (70, 170, 70)), ("b=1", (60, 60, 210)), ("unseen", (85, 85, 85)), ("ego 0", EGO_BGR[0]),
           ("ego 1", EGO_BGR[1]), ("plan", (60, 220, 60)), ("explore", (255, 150, 40)), ("seen car", (0, 220, 255)),
           ("parked", (200, 120, 60)), ("pedestrian", (30, 105, 255)), ("not seen", (235, 235, 235)),
           ("ego #rank", (230, 60, 230))]


def _inked_columns(band: np.ndarray) -> np.ndarray:
    return np.flatnonzero((band != band[0, 0]).any(axis=(0, 2)))


def test_a_legend_wider_than_the_picture_wraps_onto_more_rows_and_keeps_every_name_inside():
    wide, narrow = legend_band(2000, ENTRIES), legend_band(540, ENTRIES)
    assert wide.shape == (18, 2000, 3)  # one row where everything fits
    assert narrow.shape[1] == 540 and narrow.shape[0] >= 36  # wrapped
    assert _inked_columns(narrow).max() < 540 - 3  # nothing drawn up to the edge: no name cut
    # every entry's box is drawn, in its colour
    for _name, col in ENTRIES:
        assert (narrow.reshape(-1, 3) == np.array(col)).all(axis=1).any(), col
    assert legend_band(540, ENTRIES[:3]).shape[0] == 18


def _pixel(img, lot, x, y, s=20.0, margin=1.5):
    xmin, _, _, ymax = lot.bounds()
    return img[int(round((ymax + margin - y) * s)), int(round((x - xmin + margin) * s))].tolist()


def test_every_ego_of_a_fleet_is_drawn_in_its_colour_with_its_path(paper_lot, tmp_path):
    lot = paper_lot
    xmin, ymin, xmax, ymax = lot.bounds()
    y0 = 0.5 * (ymin + ymax)
    ego0 = np.array([[xmin + 3.0, y0, 0.0], [xmin + 8.0, y0, 0.0]])
    ego1 = np.array([[xmax - 3.0, y0 + 1.0, math.pi], [xmax - 8.0, y0 + 1.0, math.pi]])
    path = tmp_path / "fleet.png"
    render_episode(lot, ego0, (4.6, 1.85), {}, set(), None, "two egos", path, other_egos={1: (ego1, (4.6, 1.85))})
    img = cv2.imread(str(path))
    assert _pixel(img, lot, xmin + 8.0 - 1.0, y0 - 0.4) == list(EGO_BGR[0])
    assert _pixel(img, lot, xmax - 8.0 + 1.0, y0 + 0.6) == list(EGO_BGR[1])
    assert _pixel(img, lot, xmax - 5.5, y0 + 1.0) == list(EGO_BGR[1])  # its path, behind it
    legend = img[-20:]
    for col in EGO_BGR[:2]:
        assert (legend.reshape(-1, 3) == np.array(col)).all(axis=1).any()

    alone = tmp_path / "one.png"
    render_episode(lot, ego0, (4.6, 1.85), {}, set(), None, "one ego", alone)
    img = cv2.imread(str(alone))
    assert _pixel(img, lot, xmin + 8.0 - 1.0, y0 - 0.4) == list(EGO)
    assert not (img.reshape(-1, 3) == np.array(EGO_BGR[1])).all(axis=1).any()
