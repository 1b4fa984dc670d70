"""The box margin measurement (app/eval/box_margin.py): on the synthetic world's exact rear-face boxes it reads
about 0 (its own bias), on TuSimple's annotated boxes a margin of a few pixels, which the scale TTC takes off
(kinematics.scale_margin_px, docs/tracking.md)."""
import json

import numpy as np

from app import config as configuration
from app.eval.box_margin import by_band, detector_offsets, margins, side_span, synthetic_images, tusimple_images
from app.eval.tusimple_boxes import load_entries
from tests.conftest import data_path


def test_the_sides_of_a_drawn_rear_are_found():
    gray = np.full((120, 200), 120, np.uint8)
    gray[40:80, 70:130] = 40        # a dark rear 60 px wide ...
    gray[60:70, 72:80] = 220        # ... with its lamps
    gray[60:70, 120:128] = 220
    assert abs(side_span(gray, (66, 38, 134, 81)) - 60) <= 1  # boxed 8 px wider than it is


def test_exact_boxes_read_within_a_pixel_and_a_half():
    bands = by_band(margins(synthetic_images(["steady_following", "lead_braking_0p3g"], every=5)))
    assert sum(b["n"] for b in bands) >= 50
    for b in bands:
        assert abs(b["median_px"]) <= 1.5, b


def test_tusimple_boxes_of_far_cars_carry_the_margin_the_scale_ttc_takes_off():
    """Every third validation image: boxes 10-30 px high are 2-3 px wider than the car's sides (measured: +2, +2,
    +3 px; the training split's held-out images give the same, docs/tracking.md)."""
    supp = str(data_path("tusimple", "supp"))
    rows = margins(tusimple_images(supp, load_entries(supp)[::3]))
    far = [m for h, m in rows if 10 <= h < 30]
    assert len(far) >= 150
    assert 2.0 <= float(np.median(far)) <= 4.0
    assert 2.0 <= configuration.defaults()["kinematics"]["scale_margin_px"] <= 4.0


def test_the_detectors_boxes_are_drawn_as_the_annotations_are():
    """The default preset's detections on the first 40 validation images, boxes 15-40 px high: the median width
    differs from the annotated one by under a pixel (measured -0.6 px; held-out training images -0.3 to +0.4 px), so
    the detector carries the annotations' margin."""
    supp = data_path("tusimple", "supp")
    entries = json.loads((supp / "annotation.json").read_text())[:40]
    diffs = [d for h, d in detector_offsets(str(supp), entries) if 15 <= h < 40]
    assert len(diffs) >= 50
    assert abs(float(np.median(diffs))) <= 1.0
