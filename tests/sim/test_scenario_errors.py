"""Malformed scenario files give one clear ScenarioError naming the file and the key."""
import pytest

from app.sim import ScenarioError, load_scenario, render
from app.sim.scenario import SCENARIO_DIR

GOOD = """\
name: small
duration_s: 2.0
ego: {speed_kmh: 72}
vehicles:
  - {id: 1, kind: car, lane: 0, z_m: 40, speed_kmh: 60}
"""

CASES = [
    # (what is wrong, replace this, with this, the message must contain)
    ("unknown top key", "duration_s: 2.0", "duration_s: 2.0\nduraton: 3", "duraton: unknown key"),
    ("unknown vehicle key", "speed_kmh: 60}", "speed_kmh: 60, colour: red}", "vehicles[0].colour: unknown key"),
    ("wrong type", "speed_kmh: 60}", "speed_kmh: fast}", "vehicles[0].speed_kmh: expected a number, got 'fast'"),
    ("bool is not a number", "z_m: 40", "z_m: true", "vehicles[0].z_m: expected a number, got True"),
    ("negative duration", "duration_s: 2.0", "duration_s: -1", "duration_s: must be > 0.0"),
    ("missing required key", "ego: {speed_kmh: 72}", "ego: {}", "ego.speed_kmh: missing required key"),
    ("unknown vehicle kind", "kind: car", "kind: bus", "vehicles[0].kind: expected one of car, van, truck, got 'bus'"),
    ("lane outside the road", "lane: 0", "lane: 2", "vehicles[0].lane: must be <= 1, got 2"),
    ("lane change outside the road", "speed_kmh: 60}", "speed_kmh: 60, lane_changes: [{t_s: 1, to_lane: -2}]}",
     "vehicles[0].lane_changes[0].to_lane: must be >= -1, got -2"),
    ("profile not in time order", "speed_kmh: 60}",
     "speed_kmh: 60, profile: [{t_s: 1.0, accel_mps2: -1}, {t_s: 0.5, accel_mps2: 1}]}",
     "vehicles[0].profile[1].t_s: must be later than the previous entry"),
    ("negative time", "speed_kmh: 60}", "speed_kmh: 60, profile: [{t_s: -1.0, accel_mps2: -1}]}",
     "vehicles[0].profile[0].t_s: must be >= 0.0, got -1.0"),
    ("deceleration out of range", "speed_kmh: 60}", "speed_kmh: 60, profile: [{t_s: 1.0, accel_mps2: -30}]}",
     "vehicles[0].profile[0].accel_mps2: must be >= -12.0, got -30"),
    ("integer expected", "ego: {speed_kmh: 72}", "ego: {speed_kmh: 72}\nseed: 1.5", "seed: expected an integer, got 1.5"),
    ("list expected", "vehicles:\n  - {id: 1, kind: car, lane: 0, z_m: 40, speed_kmh: 60}", "vehicles: {id: 1}",
     "vehicles: expected a list, got {'id': 1}"),
    ("mapping expected", "ego: {speed_kmh: 72}", "ego: 72", "ego: expected a mapping, got 72"),
    ("duplicate id", "speed_kmh: 60}", "speed_kmh: 60}\n  - {id: 1, lane: 1, z_m: 80, speed_kmh: 60}",
     "vehicles[1].id: duplicate id 1"),
    ("bad shade", "kind: car", "kind: car, shade: pink", "vehicles[0].shade: expected one of dark, mid, light"),
    ("camera key", "duration_s: 2.0", "duration_s: 2.0\ncamera: {focal_px: 700}", "camera.focal_px: unknown key"),
    ("camera range", "duration_s: 2.0", "duration_s: 2.0\ncamera: {pitch_deg: 45}", "camera.pitch_deg: must be <= 15.0"),
    ("ego lane outside", "duration_s: 2.0", "duration_s: 2.0\nroad: {lanes: 2, ego_lane: 2}", "road.ego_lane: must be <= 1"),
    ("overpass key", "duration_s: 2.0", "duration_s: 2.0\nroad: {overpass: {z: 80}}", "road.overpass.z: unknown key"),
    ("top level not a mapping", GOOD, "- 1\n- 2\n", "<top>: expected a mapping"),
]


@pytest.mark.parametrize("what,old,new,message", CASES, ids=[c[0] for c in CASES])
def test_malformed_scenario_names_file_and_key(tmp_path, what, old, new, message):
    assert old in GOOD
    path = tmp_path / "broken.yaml"
    path.write_text(GOOD.replace(old, new, 1))
    with pytest.raises(ScenarioError) as info:
        load_scenario(str(path))
    assert str(info.value).startswith("scenario broken.yaml: ")
    assert message in str(info.value)


def test_the_good_file_loads(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    scenario = load_scenario(str(path))
    assert scenario.name == "small" and scenario.vehicles[0].speed_kmh == 60.0


def test_yaml_syntax_error_gives_line_and_column(tmp_path):
    path = tmp_path / "syntax.yaml"
    path.write_text("name: x\nvehicles: [ {id: 1\nego: {speed_kmh: 3}\n")
    with pytest.raises(ScenarioError, match=r"^scenario syntax\.yaml: YAML syntax error at line \d+, column \d+"):
        load_scenario(str(path))


def test_missing_file_and_unknown_name():
    with pytest.raises(ScenarioError, match=r"^scenario nowhere\.yaml: file not found"):
        load_scenario("/tmp/does/not/exist/nowhere.yaml")
    with pytest.raises(ScenarioError, match=r"^scenario no_such_scenario\.yaml: file not found.*shipped: .*steady_following"):
        load_scenario("no_such_scenario")


def test_bare_names_find_the_shipped_files():
    assert load_scenario("steady_following").source == str(SCENARIO_DIR / "steady_following.yaml")


def test_camera_overrides_are_validated():
    scenario = load_scenario("empty_road")
    with pytest.raises(ScenarioError, match=r"camera overrides: camera\.fx: expected a number, got 'wide'"):
        next(render(scenario, camera_overrides={"fx": "wide"}))
    with pytest.raises(ScenarioError, match=r"frame 9999 out of range"):
        next(render(scenario, frames=[9999]))
