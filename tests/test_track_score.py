"""Scoring tracks against truth: a track on a vehicle beyond the scored range ("don't care") is neither a hit nor
a false positive when most of its box lies on that vehicle (the KITTI tracking benchmark's DontCare rule)."""
from types import SimpleNamespace

from app.eval.matching import inside_matrix, iou_matrix
from app.eval.track_score import TrackScorer

# steady_following, frame 60: a truck 107.7 m ahead (beyond the 60 m scored), and the default preset's track on
# it, boxed as a car and a few pixels too wide (IoU 0.49)
TRUCK = {"id": 7, "box": [288.7, 209.6, 305.2, 235.0], "longitudinal_m": 107.7, "visible_fraction": 1.0}
TRACK_ON_TRUCK = [286.6, 217.8, 310.6, 236.3]
LEAD = {"id": 1, "box": [290.0, 240.0, 350.0, 290.0], "longitudinal_m": 25.0, "visible_fraction": 1.0}


def track(tid, box):
    return SimpleNamespace(id=tid, box=box, range_m=None)


def test_inside_is_the_share_of_the_first_box():
    assert inside_matrix([TRACK_ON_TRUCK], [TRUCK["box"]])[0, 0] > 0.6
    assert iou_matrix([TRACK_ON_TRUCK], [TRUCK["box"]])[0, 0] < 0.5
    assert inside_matrix([[0, 0, 10, 10]], [[5, 0, 20, 10]])[0, 0] == 0.5
    assert inside_matrix([[0, 0, 10, 10]], []).shape == (1, 0)


def test_a_track_mostly_on_a_dont_care_vehicle_is_no_false_positive():
    s = TrackScorer()
    s.update(0, [TRUCK, LEAD], [track(1, TRACK_ON_TRUCK), track(2, [291.0, 241.0, 349.0, 290.0])])
    assert (s.tp, s.fp, s.fn) == (1, 0, 0)


def test_a_track_mostly_beside_a_dont_care_vehicle_is_a_false_positive():
    s = TrackScorer()
    beside = [300.0, 217.8, 324.0, 236.3]  # shifted right: 5.2 of its 24 px on the truck
    assert inside_matrix([beside], [TRUCK["box"]])[0, 0] < 0.5
    s.update(0, [TRUCK, LEAD], [track(1, beside)])
    assert (s.tp, s.fp, s.fn) == (0, 1, 1)


def test_a_track_on_a_scored_vehicle_counts_even_over_a_dont_care_one():
    far = dict(TRUCK, box=[290.0, 235.0, 350.0, 290.0])  # a don't-care vehicle's box over the lead's
    s = TrackScorer()
    s.update(0, [far, LEAD], [track(1, [291.0, 241.0, 349.0, 290.0])])
    assert (s.tp, s.fp, s.fn) == (1, 0, 0)


def test_a_track_is_scored_by_its_part_in_the_image():
    """A car leaving the view on the right, half of it in the 640 px wide image: its truth box is the part in the
    image, and a track carrying the car's whole width past the image's side is that car once cut to the image."""
    leaving = {"id": 3, "box": [580.0, 200.0, 700.0, 300.0], "box_clipped": [580.0, 200.0, 639.0, 300.0],
               "longitudinal_m": 8.0, "visible_fraction": 0.5}
    whole = track(1, [582.0, 201.0, 698.0, 300.0])
    assert iou_matrix([whole.box], [leaving["box_clipped"]])[0, 0] < 0.5
    uncut = TrackScorer()
    uncut.update(0, [leaving], [whole])
    assert (uncut.tp, uncut.fp, uncut.fn) == (0, 1, 1)
    cut = TrackScorer()
    cut.update(0, [leaving], [whole], image_size=(640, 480))
    assert (cut.tp, cut.fp, cut.fn) == (1, 0, 0)
