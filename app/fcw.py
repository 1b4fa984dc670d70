"""The forward-collision warning state machine: none -> pre-warning -> warning.

Pure logic, driven one frame at a time with the lead vehicle from the core and the car's own state
from the bus; tests feed it made-up sequences and check which level comes at which second. It runs in
the supervisor because the inputs that gate it (ego speed, brake, turn signals) arrive there.

A warning needs a threat both ways: a short time to collision AND a deceleration the driver would
need that is not trivial (a short TTC at walking-pace closing is stop-and-go, not a threat). A very
high required deceleration warns on its own. Users complain most about false warnings, so every
gate below errs towards silence where the physics allows, and the defaults are set so that the US
NCAP FCW confirmation tests (warn by TTC 2.1 s stopped lead, 2.4 s braking lead, 2.0 s slower lead)
pass with margin on the synthetic suite (docs/RESULTS.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

from app.contracts.config_key import key as _key
from app.contracts.fcw_level import FcwLevel
from app.contracts.ttc_source import TtcSource

NONE, PREWARNING, WARNING = FcwLevel.NONE, FcwLevel.PREWARNING, FcwLevel.WARNING


# The configuration section `fcw` (merged into app/config.py's registry).
FCW_SCHEMA = {
    "ttc_warning_s": _key(3.0, "s; warn when the TTC to the lead falls below this; NCAP asks for a warning by "
                               "2.1-2.4 s, and 3.0 leaves ~0.6 s for range-rate filter lag and one frame of latency",
                          0.5, 10.0),
    "ttc_prewarning_s": _key(4.0, "s; pre-warning (visual only) below this TTC", 0.5, 15.0),
    "min_decel_mps2": _key(1.0, "m/s^2; a TTC warning also needs the ego car to need at least this deceleration "
                                "(v_rel^2 / 2 gap - a_rel): below it closing is slow (stop-and-go), not a threat; "
                                "1.0 still lets a lead braking at 0.3 g warn by TTC 2.4 s", 0.0, 10.0),
    "decel_warning_mps2": _key(5.0, "m/s^2; a required deceleration above this warns whatever the TTC "
                                    "(half of a full brake: the driver must act now)", 1.0, 15.0),
    "min_ego_speed_mps": _key(5.0, "m/s; no warning below this ego speed (parking and queues; openpilot's "
                                   "legacy FCW used 5 m/s)", 0.0, 50.0),
    "min_lead_seen_s": _key(0.5, "s; the lead must have been tracked this long: one-frame ghosts never warn, "
                                 "and 0.5 s still leaves time at 100 km/h", 0.0, 10.0),
    "hysteresis_s": _key(0.5, "s; a level ends only once TTC is this much above its threshold (no flicker)",
                         0.0, 5.0),
    "min_warning_s": _key(1.0, "s; a warning lasts at least this long so the buzzer is heard", 0.0, 10.0),
    "min_gap_s": _key(5.0, "s; at most one new warning in this time (openpilot's legacy FCW: one per 5 s)",
                      0.0, 60.0),
    "suppress_on_brake": _key(True, "no new warning while the driver brakes: they are already reacting"),
    "suppress_on_turn_signal": _key(True, "no new warning while a turn signal is on: the driver is changing "
                                          "lane around the lead"),
    "use_scale_ttc": _key(True, "while the range rate is not yet known (a new track), use the scale-based TTC "
                                "(needs no calibration); once the range filter knows the rate it decides"),
    "use_accel": _key(True, "take the relative acceleration into account (TTC and required deceleration with "
                            "a braking lead): a lead braking at 0.3 g is otherwise caught late"),
    "max_closing_margin_mps": _key(3.0, "m/s; a TTC is believed only if the closing speed it implies (gap / TTC) "
                                        "is at most the ego speed plus this: traffic ahead does not drive "
                                        "backwards, so anything faster is a measurement error", 0.0, 50.0),
    "min_threat_s": _key(0.1, "s; a threat must last this long (3 frames at 30 fps) before it warns or "
                              "pre-warns: one noisy frame never sounds the buzzer nor lights the display",
                         0.0, 2.0),
    "hold_without_ttc_s": _key(1.0, "s; while the lead's TTC is unknown (refused as a bad estimate, "
                                    "max_closing_margin_mps, or not measured: the range rate not settled and no "
                                    "scale change fitted), a level already raised holds this long: no estimate is "
                                    "not an all-clear (a scale TTC 15 % short of a stopped car at 100 km/h would "
                                    "otherwise end the warning 1.5 s before contact)", 0.0, 5.0),
}


@dataclass
class FcwParams:
    ttc_warning_s: float = FCW_SCHEMA["ttc_warning_s"]["default"]
    ttc_prewarning_s: float = FCW_SCHEMA["ttc_prewarning_s"]["default"]
    min_decel_mps2: float = FCW_SCHEMA["min_decel_mps2"]["default"]
    decel_warning_mps2: float = FCW_SCHEMA["decel_warning_mps2"]["default"]
    min_ego_speed_mps: float = FCW_SCHEMA["min_ego_speed_mps"]["default"]
    min_lead_seen_s: float = FCW_SCHEMA["min_lead_seen_s"]["default"]
    hysteresis_s: float = FCW_SCHEMA["hysteresis_s"]["default"]
    min_warning_s: float = FCW_SCHEMA["min_warning_s"]["default"]
    min_gap_s: float = FCW_SCHEMA["min_gap_s"]["default"]
    suppress_on_brake: bool = FCW_SCHEMA["suppress_on_brake"]["default"]
    suppress_on_turn_signal: bool = FCW_SCHEMA["suppress_on_turn_signal"]["default"]
    use_scale_ttc: bool = FCW_SCHEMA["use_scale_ttc"]["default"]
    use_accel: bool = FCW_SCHEMA["use_accel"]["default"]
    max_closing_margin_mps: float = FCW_SCHEMA["max_closing_margin_mps"]["default"]
    min_threat_s: float = FCW_SCHEMA["min_threat_s"]["default"]
    hold_without_ttc_s: float = FCW_SCHEMA["hold_without_ttc_s"]["default"]

    @classmethod
    def from_config(cls, section: dict) -> "FcwParams":
        return cls(**section)


@dataclass
class Lead:
    """The lead vehicle as the core reports it (None where not available)."""

    id: int
    range_m: Optional[float]
    range_rate_mps: Optional[float]
    ttc_s: Optional[float]
    ttc_scale_s: Optional[float]
    range_accel_mps2: Optional[float] = None


@dataclass
class EgoState:
    """The car's own state from the bus; None = not available or stale (never guessed)."""

    speed_mps: Optional[float]
    brake: Optional[bool] = None
    turn_left: Optional[bool] = None
    turn_right: Optional[bool] = None


@dataclass
class FcwOutput:
    level: FcwLevel
    ttc_used_s: Optional[float]
    ttc_source: Optional[TtcSource]  # None: no TTC decided
    lead_id: Optional[int]
    lead_range_m: Optional[float]
    lead_range_rate_mps: Optional[float]
    required_decel_mps2: Optional[float]
    suppressed_by: Optional[str]    # why a threat did not warn: "ego_speed_unavailable", "brake", ...
    changed: bool                   # level differs from the previous step
    ego_speed_mps: Optional[float] = None  # the ego speed the decision was made with (None: unknown)


@dataclass
class FcwStateMachine:
    params: FcwParams = field(default_factory=FcwParams)
    # camera to bumper (range_m is from the camera): the core's kinematics.ego_front_m, which owns it
    ego_front_m: float = field(kw_only=True)

    def __post_init__(self) -> None:
        self.level = NONE
        self._lead_id: Optional[int] = None
        self._lead_since: Optional[float] = None
        self._warning_since: Optional[float] = None
        self._warning_ttc = math.inf          # TTC when the last warning started
        self._last_warning_end = -math.inf
        self._threat_since: Optional[float] = None
        self._pre_since: Optional[float] = None
        self._unknown_since: Optional[float] = None  # first step of the current run without a TTC

    def _accel(self, lead: Lead) -> float:
        """Relative acceleration that makes things worse (< 0: closing speeds up), else 0."""
        a = lead.range_accel_mps2
        return min(0.0, a) if (self.params.use_accel and a is not None) else 0.0

    def _ttc(self, lead: Lead) -> tuple[Optional[float], Optional[TtcSource]]:
        """Once the range filter knows the range rate it decides (and says "not closing" with None);
        before that the scale-based TTC stands in."""
        if lead.range_rate_mps is not None:
            ttc, src = lead.ttc_s, TtcSource.RANGE
            a = self._accel(lead)
            if a < 0 and lead.range_m is not None:
                # gap + v t + a t^2 / 2 = 0: the first contact with the closing speeding up
                gap = max(0.0, lead.range_m - self.ego_front_m)
                v = lead.range_rate_mps
                t_acc = (-v - math.sqrt(v * v - 2.0 * a * gap)) / a
                if ttc is None or t_acc < ttc:
                    ttc, src = t_acc, TtcSource.RANGE_ACCEL
            return (ttc, src) if ttc is not None else (None, None)
        if self.params.use_scale_ttc and lead.ttc_scale_s is not None:
            return lead.ttc_scale_s, TtcSource.SCALE
        return None, None

    def _required_decel(self, lead: Lead) -> Optional[float]:
        """v_rel^2 / (2 gap) - a_rel: the extra deceleration that ends the closing just at the lead,
        with the lead's own braking (a_rel < 0) added."""
        if lead.range_m is None or lead.range_rate_mps is None:
            return None
        a = self._accel(lead)
        if lead.range_rate_mps >= 0 and a >= 0:
            return None
        gap = max(0.1, lead.range_m - self.ego_front_m)
        return min(0.0, lead.range_rate_mps) ** 2 / (2.0 * gap) - a

    def step(self, t_s: float, lead: Optional[Lead], ego: EgoState) -> FcwOutput:
        p = self.params
        if lead is None or lead.id != self._lead_id:
            self._lead_id = None if lead is None else lead.id
            self._lead_since = None if lead is None else t_s
        ttc, source = self._ttc(lead) if lead else (None, None)
        refused = False
        if ttc is not None and ego.speed_mps is not None and lead.range_m is not None and ttc > 0:
            closing = max(0.0, lead.range_m - self.ego_front_m) / ttc
            if closing > ego.speed_mps + p.max_closing_margin_mps:
                ttc, source = None, None  # physically impossible for traffic ahead: a bad estimate
                refused = True
        # no TTC and nothing that says "not closing" (a settled range rate does)
        unknown = refused or (lead is not None and ttc is None and lead.range_rate_mps is None)
        self._unknown_since = (self._unknown_since if self._unknown_since is not None else t_s) if unknown else None
        a_req = self._required_decel(lead) if lead else None
        seen_s = t_s - self._lead_since if self._lead_since is not None else 0.0

        # The threat as physics sees it, before any gate.
        threat = NONE
        if ttc is not None:
            margin = p.hysteresis_s if self.level >= WARNING else 0.0
            if ttc <= p.ttc_warning_s + margin and (a_req is None or a_req >= p.min_decel_mps2):
                threat = WARNING
            elif ttc <= p.ttc_prewarning_s + (p.hysteresis_s if self.level >= PREWARNING else 0.0):
                threat = PREWARNING
        if a_req is not None and a_req >= p.decel_warning_mps2:
            threat = WARNING
        # An unknown TTC tells nothing about the threat: the level already raised holds for a while.
        if unknown and t_s - self._unknown_since <= p.hold_without_ttc_s + 1e-9:
            threat = max(threat, self.level)

        # A warning-level threat must persist for min_threat_s before it counts, and so must any threat
        # before the display shows a pre-warning (a far car's noisy TTC flickers below 4 s for a frame).
        if threat == WARNING:
            self._threat_since = t_s if self._threat_since is None else self._threat_since
            if self.level < WARNING and t_s - self._threat_since < p.min_threat_s - 1e-9:
                threat = PREWARNING
        else:
            self._threat_since = None
        if threat > NONE:
            self._pre_since = t_s if self._pre_since is None else self._pre_since
            if self.level == NONE and t_s - self._pre_since < p.min_threat_s - 1e-9:
                threat = NONE
        else:
            self._pre_since = None

        suppressed = None
        if threat > NONE:
            if ego.speed_mps is None:
                suppressed = "ego_speed_unavailable"
            elif ego.speed_mps < p.min_ego_speed_mps:
                suppressed = "ego_speed_low"
            elif seen_s < p.min_lead_seen_s:
                suppressed = "lead_too_new"
            elif p.suppress_on_brake and ego.brake and self.level < WARNING:
                suppressed = "brake"
            elif p.suppress_on_turn_signal and (ego.turn_left or ego.turn_right) and self.level < WARNING:
                suppressed = "turn_signal"
        level = NONE if suppressed else threat

        # A warning, once raised, holds for min_warning_s; a new one waits min_gap_s after the last.
        if self.level == WARNING and level < WARNING and t_s - self._warning_since < p.min_warning_s:
            level = WARNING
        if level == WARNING and self.level < WARNING:
            # at most one warning per min_gap_s, unless the threat is worse than when the last one started
            if t_s - self._last_warning_end < p.min_gap_s and (ttc is None or ttc >= self._warning_ttc):
                level, suppressed = PREWARNING, "min_gap"
            else:
                self._warning_since = t_s
                self._warning_ttc = ttc if ttc is not None else 0.0
        if self.level == WARNING and level < WARNING:
            self._last_warning_end = t_s
        changed = level != self.level
        self.level = level
        return FcwOutput(level=level, ttc_used_s=ttc, ttc_source=source,
                         lead_id=lead.id if lead else None, lead_range_m=lead.range_m if lead else None,
                         lead_range_rate_mps=lead.range_rate_mps if lead else None, required_decel_mps2=a_req,
                         suppressed_by=suppressed, changed=changed, ego_speed_mps=ego.speed_mps)
