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


def test_a_car_stopped_close_ahead_without_markings_is_tracked_and_ranged_within_8_percent():
    """stopped_close_no_markings, default preset: the car ahead (id 1, real-looking) crawls, stops, and stands 6.7 m
    ahead with queues beside it on a road without lines. It is tracked (a confirmed track at IoU >= 0.5) in >= 95 %
    of the frames and every matched range is within 8 % of the truth. Measured 267 of 270 frames (the first three
    confirm it), range error median 1.1 %, max 3.1 %: the horizon follows only a believed lane model's vanishing
    point, so the vehicle sides that the lane stage assembles into "lanes" here do not move it."""
    rows = []  # (a confirmed track matches car 1, that track's relative range error)

    def on_result(r, decision, truth):
        v1 = next(v for v in truth if v["id"] == 1)
        confirmed = [t for t in r.tracks if t.confirmed]
        pair = match([v1["box_clipped"]], [t.box for t in confirmed], 0.5)
        err = None
        if pair and confirmed[pair[0][1]].range_m is not None:
            err = (confirmed[pair[0][1]].range_m - v1["longitudinal_m"]) / v1["longitudinal_m"]
        rows.append((bool(pair), err))

    replay_scenario("stopped_close_no_markings", on_result=on_result, progress=False)
    assert len(rows) == 270
    tracked = sum(row[0] for row in rows)
    assert tracked >= 0.95 * len(rows), f"the car ahead tracked in {tracked} of {len(rows)} frames"
    errors = [abs(e) for ok, e in rows if ok and e is not None]
    assert len(errors) >= 0.95 * len(rows)
    assert max(errors) <= 0.08, f"range error up to {max(errors):.1%}"
