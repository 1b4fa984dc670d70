"""The vehicle_shape section (csrc/geometry/vehicle_shape.hpp): the vehicles' width, tallest height and aspects,
one key each, reach the parts that read them."""
from __future__ import annotations

import pytest

from app import config as configuration
from app.core import InvalidArgument, Pipeline
from tests import thesis_scenes


def _boxes(**sections) -> list[tuple[float, float, float, float, float]]:
    """The thesis detector's boxes on steady_following frame 60 (two vehicles ahead, plain rear faces)."""
    image = thesis_scenes.frames("steady_following")[60].image
    with Pipeline(thesis_scenes.config("steady_following", **sections)) as p:
        return p.detect(image).rows()


def test_the_aspect_is_the_height_of_a_box_whose_top_is_not_searched():
    """With the top search off, every verified box is vehicle_shape.aspect widths tall: 0.8 by default, 1.2 when
    set, on the same bottoms and sides."""
    nominal = _boxes(verify={"find_top": False})
    tall = _boxes(verify={"find_top": False}, vehicle_shape={"aspect": 1.2})
    assert len(nominal) == 2 and len(tall) == 2
    for (l0, t0, r0, b0, _), (l1, t1, r1, b1, _) in zip(nominal, tall):
        assert (l1, r1, b1) == pytest.approx((l0, r0, b0), abs=1e-3)  # float32 boxes: bottom = top + height
        assert (b0 - t0) / (r0 - l0) == pytest.approx(0.8, rel=1e-3)
        assert (b1 - t1) / (r1 - l1) == pytest.approx(1.2, rel=1e-3)


def test_the_top_search_stops_at_the_tallest_aspect():
    """vehicle_shape.max_aspect bounds the verification's top search: no box is taller than 0.85 widths when it
    is set there (a top found lower than top_min_aspect falls back to aspect, 0.8)."""
    assert any((b - t) / (r - l) > 0.85 for l, t, r, b, _ in _boxes())  # at 1.6: a top found 1.05 widths up
    boxes = _boxes(vehicle_shape={"max_aspect": 0.85, "top_min_aspect": 0.82})
    assert len(boxes) == 2
    assert all((b - t) / (r - l) <= 0.85 + 1e-3 for l, t, r, b, _ in boxes)


def test_a_tallest_vehicle_below_the_cascades_lowest_is_refused():
    """The cascade scans each window size in the rows between its lowest and tallest vehicle: a tallest one below
    the lowest (1.0 m) leaves no rows, and building the part says which keys to change."""
    values = {"pipeline": {"preset": "paper004"}, "vehicle_shape": {"max_height_m": 0.8}}
    with pytest.raises(InvalidArgument, match=r"vehicle_shape\.max_height_m \(0\.8 m\) must exceed "
                                              r"cascade\.min_vehicle_height_m \(1 m\).*raise the first or lower"):
        Pipeline(configuration.core_sections(configuration.load(None, values)))
