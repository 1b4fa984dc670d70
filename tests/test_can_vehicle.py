"""Vehicle inputs: mapped by DBC, message and signal(s), converted to SI, stale inputs reported and
never guessed; mapping mistakes named by their configuration key."""
from __future__ import annotations

import math

import can
import cantools
import pytest

from app.can import VehicleInput, VehicleInputError
from app.can.config_schema import defaults

CAR_DBC = '''VERSION ""
NS_ :
BS_:
BU_: CAR
BO_ 170 WHEELS: 8 CAR
 SG_ WS_FL : 0|16@1+ (0.01,0) [0|655.35] "km/h" CAR
 SG_ WS_FR : 16|16@1+ (0.01,0) [0|655.35] "km/h" CAR
 SG_ WS_RL : 32|16@1+ (0.01,0) [0|655.35] "km/h" CAR
 SG_ WS_RR : 48|16@1+ (0.01,0) [0|655.35] "km/h" CAR
BO_ 36 MOTION: 8 CAR
 SG_ YAW : 0|16@1- (0.01,0) [-327.68|327.67] "deg/s" CAR
 SG_ BRAKE_PRESSED : 16|1@1+ (1,0) [0|1] "" CAR
 SG_ ODD : 24|8@1+ (1,0) [0|255] "furlong/fortnight" CAR
BO_ 1556 LEVERS: 8 CAR
 SG_ TURN : 0|2@1+ (1,0) [0|3] "" CAR
VAL_ 1556 TURN 0 "off" 1 "left" 2 "right" ;
'''


@pytest.fixture
def car(tmp_path):
    path = tmp_path / "car.dbc"
    path.write_text(CAR_DBC)
    return path, cantools.database.load_string(CAR_DBC)


def vehicle_cfg(dbc, **keys):
    cfg = defaults()["vehicle"]
    cfg.update({"dbc": str(dbc), "speed_message": "WHEELS", "speed_signals": "WS_FL,WS_FR,WS_RL,WS_RR", **keys})
    return cfg


def frame(db, name, t, **signals):
    m = db.get_message_by_name(name)
    return can.Message(timestamp=t, arbitration_id=m.frame_id, is_extended_id=False, data=m.encode(signals),
                       channel="can0")


def wheels(db, t, fl, fr, rl, rr):
    return frame(db, "WHEELS", t, WS_FL=fl, WS_FR=fr, WS_RL=rl, WS_RR=rr)


def test_speed_is_the_mean_of_the_wheels_in_metres_per_second(car):
    path, db = car
    vi = VehicleInput.from_config(vehicle_cfg(path))
    vi.on_message(wheels(db, 0.0, 72.0, 72.4, 71.6, 72.0))
    s = vi.snapshot(0.01)
    assert s.speed_mps == pytest.approx(72.0 / 3.6)
    assert s.inputs["speed"].age_s == pytest.approx(0.01) and not s.inputs["speed"].stale
    assert not s.faults


@pytest.mark.parametrize("combine, expected_kmh", [("min", 71.6), ("max", 72.4), ("first", 72.0)])
def test_other_combinations_and_an_explicit_unit(car, combine, expected_kmh):
    path, db = car
    vi = VehicleInput.from_config(vehicle_cfg(path, speed_combine=combine, speed_unit="km/h", speed_scale=1.02))
    vi.on_message(wheels(db, 0.0, 72.0, 72.4, 71.6, 72.0))
    assert vi.snapshot(0.0).speed_mps == pytest.approx(expected_kmh / 3.6 * 1.02)


def test_a_stale_speed_is_reported_and_never_guessed(car):
    path, db = car
    vi = VehicleInput.from_config(vehicle_cfg(path, speed_stale_after_s=0.2))
    for k in range(50):  # 50 Hz for 1 s, then silence
        vi.on_message(wheels(db, k * 0.02, 50.0, 50.0, 50.0, 50.0))
    assert vi.snapshot(0.98 + 0.2).speed_mps == pytest.approx(50 / 3.6)
    late = vi.snapshot(0.98 + 0.21)
    assert late.speed_mps is None and late.inputs["speed"].stale and late.faults == {"ego_speed_stale"}
    assert late.stale_inputs == ("speed",) and late.ego_speed_fresh is False
    assert late.inputs["speed"].age_s == pytest.approx(0.21)
    vi.on_message(wheels(db, 1.5, 40.0, 40.0, 40.0, 40.0))  # comes back
    back = vi.snapshot(1.5)
    assert back.speed_mps == pytest.approx(40 / 3.6) and not back.faults and back.ego_speed_fresh is True


def test_a_missing_speed_is_no_fault_during_start_up_but_is_never_available(car):
    path, _db = car
    vi = VehicleInput.from_config(vehicle_cfg(path, speed_stale_after_s=0.5))
    first = vi.snapshot(100.0)
    assert first.speed_mps is None and first.inputs["speed"].stale and not first.faults
    assert vi.snapshot(100.49).faults == set()
    assert vi.snapshot(100.5).faults == {"ego_speed_stale"}


def test_without_a_speed_mapping_fcw_is_told_not_available_but_it_is_no_fault():
    vi = VehicleInput.from_config(defaults()["vehicle"])
    s = vi.snapshot(10.0)
    assert s.speed_mps is None and not s.inputs["speed"].configured
    assert not s.faults and s.ego_speed_fresh is None  # the health monitor's "not configured"


def test_yaw_rate_brake_and_turn_signals(car):
    path, db = car
    cfg = vehicle_cfg(path, yaw_rate_message="MOTION", yaw_rate_signals="YAW", yaw_rate_scale=-1.0,
                      brake_message="MOTION", brake_signals="BRAKE_PRESSED",
                      turn_left_message="LEVERS", turn_left_signals="TURN", turn_left_true_value=1,
                      turn_right_message="LEVERS", turn_right_signals="TURN", turn_right_true_value=2)
    vi = VehicleInput.from_config(cfg)
    vi.on_message(wheels(db, 0.0, 30.0, 30.0, 30.0, 30.0))
    vi.on_message(frame(db, "MOTION", 0.0, YAW=-5.73, BRAKE_PRESSED=1, ODD=0))
    vi.on_message(frame(db, "LEVERS", 0.0, TURN=2))
    s = vi.snapshot(0.1)
    assert s.yaw_rate_rps == pytest.approx(5.73 * math.pi / 180)
    assert s.brake is True and s.turn_left is False and s.turn_right is True
    assert not s.faults
    s = vi.snapshot(0.6)  # yaw and brake go stale after 0.5 s, the turn signal after 2 s
    assert s.yaw_rate_rps is None and s.brake is None and s.turn_right is True
    assert s.stale_inputs == ("speed", "yaw_rate", "brake") and s.faults == {"ego_speed_stale"}


def test_channel_filter_and_invalid_frames(car):
    path, db = car
    vi = VehicleInput.from_config(vehicle_cfg(path, channel="can0"))
    other = wheels(db, 0.0, 99.0, 99.0, 99.0, 99.0)
    other.channel = "can1"
    vi.on_message(other)
    assert vi.snapshot(0.0).speed_mps is None
    vi.on_message(wheels(db, 0.0, 36.0, 36.0, 36.0, 36.0))
    short = can.Message(timestamp=0.05, arbitration_id=170, is_extended_id=False, data=b"\x01\x02\x03",
                        channel="can0")
    vi.on_message(short)
    s = vi.snapshot(0.1)
    assert s.speed_mps == pytest.approx(10.0) and not s.faults  # the bad frame is dropped, the good one used
    stats = vi.stats()["car.dbc"]
    assert stats["ignored_other_channel"] == 1 and stats["drops"] == {"wrong_length": 1}
    assert stats["accepted"] == 1


@pytest.mark.parametrize("keys, message", [
    ({"speed_message": "WHEEL"}, "vehicle.speed_message: WHEEL is not in"),
    ({"speed_message": "WHEEL"}, "did you mean WHEELS?"),
    ({"speed_signals": "WS_FL,WS_FX"}, "vehicle.speed_signals: WS_FX is not a signal of WHEELS"),
    ({"speed_signals": ""}, "vehicle.speed_signals: give the signal name"),
    ({"yaw_rate_message": "MOTION", "yaw_rate_signals": "ODD"},
     "vehicle.yaw_rate_unit: the DBC gives ['furlong/fortnight']"),
])
def test_mapping_mistakes_name_the_key(car, keys, message):
    path, _db = car
    with pytest.raises(VehicleInputError) as e:
        VehicleInput.from_config(vehicle_cfg(path, **keys))
    assert message in str(e.value)


def test_a_car_dbc_that_does_not_parse_names_key_and_file(tmp_path):
    bad = tmp_path / "car.dbc"
    bad.write_text("BO_ this is : not a DBC\n")
    with pytest.raises(VehicleInputError) as e:
        VehicleInput.from_config(vehicle_cfg(bad))
    assert "vehicle.speed_dbc / vehicle.dbc" in str(e.value) and str(bad) in str(e.value)
    with pytest.raises(VehicleInputError, match="no such DBC file"):
        VehicleInput.from_config(vehicle_cfg(tmp_path / "absent.dbc"))
    cfg = vehicle_cfg("")
    with pytest.raises(VehicleInputError, match="neither vehicle.speed_dbc nor vehicle.dbc"):
        VehicleInput.from_config(cfg)
