"""Forward-collision warnings through the whole stack (renderer, core, supervisor, CAN encoding), read
back from the output CAN log with cantools as the car would: the US NCAP FCW confirmation scenarios
warn in time, and the everyday scenarios users complain about stay quiet."""
from __future__ import annotations

import filecmp

import pytest

from app.eval.fcw_scenarios import NO_WARNING, REQUIRED_TTC_S, evaluate


@pytest.mark.parametrize("scenario", sorted(REQUIRED_TTC_S))
def test_ncap_scenario_warns_before_required_ttc(scenario):
    r = evaluate(scenario)
    assert r["warnings"] >= 1, f"{scenario}: no warning at all"
    # the true TTC (ground truth) when the first warning frame went out on the bus
    assert r["true_ttc_s"] is not None and r["true_ttc_s"] >= r["required_ttc_s"], (
        f"{scenario}: warned at true TTC {r['true_ttc_s']:.2f} s, required >= {r['required_ttc_s']} s")
    assert r["ttc_used_s"] is not None and 0 < r["ttc_used_s"] <= 3.5
    # and, the driver not braking, it stays on while the true TTC is below the required one (down to 0.5 s)
    assert not r["dropped_at_ttc_s"], f"{scenario}: the warning ended at true TTC {r['dropped_at_ttc_s']} s"
    # the TTC it decides on, against the true one while that is 1-5 s: known on most of those frames (1.5 s and
    # more at 30 fps), biased by at most 30 % (measured: -1 % to +24 %, the far stopped car at 100 km/h read late)
    # and within 60 % on nine frames in ten (measured 11-54 %)
    acc = r["ttc_accuracy"]
    assert acc["frames"] >= 45 and abs(acc["median"]) <= 0.30 and acc["p90_abs"] <= 0.60, acc


@pytest.mark.parametrize("scenario", NO_WARNING)
def test_no_false_warning(scenario):
    r = evaluate(scenario)
    assert r["warnings"] == 0, f"{scenario}: false warning at t={r['first_warning_t_s']} s"


def test_two_replays_give_identical_can_logs(tmp_path):
    from app.replay import replay_scenario

    for name in ("a", "b"):
        replay_scenario("cut_in", can_out=str(tmp_path / f"{name}.log"), tracks_path=str(tmp_path / f"{name}.jsonl"),
                        progress=False)
    assert filecmp.cmp(tmp_path / "a.log", tmp_path / "b.log", shallow=False)
    assert filecmp.cmp(tmp_path / "a.jsonl", tmp_path / "b.jsonl", shallow=False)
    assert (tmp_path / "a.log").stat().st_size > 10_000
