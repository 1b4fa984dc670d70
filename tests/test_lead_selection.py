"""Lead selection through a lead's lane change: it stays the lead until it has left the lane, and comes
back when it returns; no flicker in between."""
from __future__ import annotations

from app.eval.matching import match
from app.replay import replay_scenario

HALF_LANE_M = 1.8


def test_lead_changing_lanes_stops_being_lead_once_it_has_left():
    rows = []

    def on_result(r, decision, truth):
        v1 = next((v for v in truth if v["id"] == 1), None)
        lead = next((t for t in r.tracks if t.id == r.lead_id), None)
        is_v1 = bool(lead and v1 and match([v1["box_clipped"]], [lead.box], 0.3))
        rows.append((r.t_s, r.lead_id, is_v1, v1))

    replay_scenario("lane_change", on_result=on_result, progress=False)
    settled = [row for row in rows if row[0] > 0.5]
    # in its lane: the lead
    centred = [row for row in settled if abs(row[3]["lateral_m"]) < 0.5]
    assert centred and all(row[2] for row in centred)
    # wholly in the other lane (near edge past the line by 0.2 m): not the lead
    gone = [row for row in settled if abs(row[3]["lateral_m"]) - row[3]["width_m"] / 2 > HALF_LANE_M + 0.2]
    assert gone and not any(row[2] for row in gone)
    # the id it had as lead before is the id it has as lead after returning (one track throughout)
    v1_ids = {row[1] for row in settled if row[2]}
    assert len(v1_ids) == 1
    changes = sum(1 for a, b in zip(settled, settled[1:]) if a[1] != b[1])
    assert changes <= 4, f"lead changed {changes} times"
