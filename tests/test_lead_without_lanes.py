"""The lead without lane markings: the ego path from the yaw rate and the vehicle width. On roads with no
painted lines the stopped lead at 72 km/h is still warned in time, and in congestion the car ahead is the
lead from 40 m down to 5 m."""
from __future__ import annotations

from app.eval.fcw_scenarios import evaluate
from app.eval.matching import match
from app.replay import replay_scenario


def test_stopped_lead_without_markings_warned_before_ttc_2_1_s():
    r = evaluate("stopped_lead_72kmh_no_markings")
    assert r["warnings"] >= 1, "no warning at all"
    assert r["true_ttc_s"] is not None and r["true_ttc_s"] >= 2.1, f"warned at true TTC {r['true_ttc_s']}"


def test_congestion_without_markings_car_ahead_is_the_lead_from_40_to_5_m():
    rows = []  # (true range of the car ahead, a confirmed track is on it, it is the lead)

    def on_result(r, decision, truth):
        v1 = next(v for v in truth if v["id"] == 1)
        lead = next((t for t in r.tracks if t.id == r.lead_id), None)
        tracked = any(match([v1["box_clipped"]], [t.box], 0.3) for t in r.tracks if t.confirmed)
        is_v1 = bool(lead and match([v1["box_clipped"]], [lead.box], 0.3))
        rows.append((v1["longitudinal_m"], tracked, is_v1))

    replay_scenario("congestion_no_markings", on_result=on_result, progress=False)
    assert rows[-1][0] < 6.0  # the scenario does close to 5 m
    # after the ~10 frames the tracker takes to confirm, from 40 m down to the end
    judged = [row for row in rows[15:] if row[0] <= 40.0]
    assert len(judged) > 200
    tracked = [row for row in judged if row[1]]
    # whenever the car ahead is tracked it is the lead (measured: 288 of 289 frames); the lane stage finds
    # "lanes" on the unmarked road (vehicle sides) and the lead selection must not believe them
    assert sum(row[2] for row in tracked) >= 0.98 * len(tracked)
    # the thesis tracker loses it for 0.8 s around 30 m (measured 91.7 % tracked): the lead overall
    share = sum(row[2] for row in judged) / len(judged)
    assert share >= 0.90, f"the car ahead was the lead in {share:.0%} of the frames"


def test_unmarked_road_lanes_are_not_believed_even_with_more_marking_points():
    """lanes.cross_inner_edges finds more marking points, also on the unmarked road's vehicle rears and barrier,
    and the lane stage assembles (and with lanes.curve_enabled bends) "lanes" from them; their marking points lie
    inside the confirmed vehicles' boxes or far out, not along the road (lanes/lane_evidence.hpp), so the model is
    uncertain and the lead comes from the ego path. Measured with both on: the car ahead is tracked in all frames
    from 40 m down and is the lead in 0.997 of them; without the evidence check (lanes.evidence_min 0) 0.92, and
    0.83 with cross_inner_edges and straight boundaries."""
    rows = []

    def on_result(r, decision, truth):
        v1 = next(v for v in truth if v["id"] == 1)
        lead = next((t for t in r.tracks if t.id == r.lead_id), None)
        tracked = any(match([v1["box_clipped"]], [t.box], 0.3) for t in r.tracks if t.confirmed)
        rows.append((v1["longitudinal_m"], tracked, bool(lead and match([v1["box_clipped"]], [lead.box], 0.3))))

    replay_scenario("congestion_no_markings", on_result=on_result, progress=False,
                    overrides={"lanes": {"cross_inner_edges": True, "curve_enabled": True}})
    judged = [row for row in rows[15:] if row[0] <= 40.0]
    tracked = [row for row in judged if row[1]]
    assert len(tracked) >= 0.95 * len(judged)
    assert sum(row[2] for row in tracked) >= 0.98 * len(tracked)
    share = sum(row[2] for row in judged) / len(judged)
    assert share >= 0.95, f"the car ahead was the lead in {share:.0%} of the frames"
