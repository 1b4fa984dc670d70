"""The configuration keys of the CAN layer, in the registry's form (merged into ``app.config``):
``{section: {key: {"default", "type", "doc", ["min", "max"], ["choices"]}}}``. Every doc says the
unit, what the key does and why the default is what it is.

Vehicle inputs are flat: for each input NAME in INPUTS, ``NAME_message`` (empty = not configured),
``NAME_signals`` (comma-separated; several are combined by ``NAME_combine``), ``NAME_dbc`` (empty =
``vehicle.dbc``), ``NAME_stale_after_s``; numbers also ``NAME_unit``, ``NAME_scale``,
``NAME_offset``; on/off inputs ``NAME_true_value``.
"""
from __future__ import annotations

from app.contracts.config_key import key

INTERFACES = ("socketcan|virtual|slcan|socketcand|pcan|kvaser|vector|ixxat|gs_usb|neovi|nican|nixnet|"
              "iscan|systec|usb2can|cantact|canalystii|seeedstudio|robotell|serial|udp_multicast|etas|neousys")

# input name -> (kind, SI unit, unit choices, default stale_after_s, what it is, why that stale time)
INPUTS = {
    "speed": ("number", "m/s", "dbc|m/s|km/h|mph", 0.5,
              "ego speed over ground (FCW needs it: without a fresh value no warning is given)",
              "25-50 periods of the usual 50-100 Hz wheel-speed message, yet short enough that FCW never runs "
              "on a speed half a second old"),
    "yaw_rate": ("number", "rad/s", "dbc|rad/s|deg/s", 0.5, "ego yaw rate, positive turning left",
                 "many periods of the usual 50-100 Hz"),
    "brake": ("flag", "", "", 0.5, "brake pedal pressed", "many periods of the usual 10-100 Hz"),
    "turn_left": ("flag", "", "", 2.0, "left turn signal on",
                  "turn-signal messages often come at only 1-2 Hz"),
    "turn_right": ("flag", "", "", 2.0, "right turn signal on",
                   "turn-signal messages often come at only 1-2 Hz"),
}


_k = key


def _input_keys(name: str) -> dict:
    kind, si, units, stale, what, why_stale = INPUTS[name]
    example = " (e.g. the four wheel speeds)" if name == "speed" else ""
    keys = {
        f"{name}_dbc": _k("", f"path; DBC file for the {name} input when it is not vehicle.dbc; empty = vehicle.dbc"),
        f"{name}_message": _k("", f"DBC message carrying the {what}; empty = not configured"
                                  + (" (FCW is then never available)" if name == "speed" else "")),
        f"{name}_signals": _k("", f"signal name(s) in that message, comma-separated; several are combined by "
                                  f"{name}_combine{example}"),
        f"{name}_combine": _k("mean", "how several signals make one value: mean, min, max or first; mean because "
                                      "a car's reference speed is the mean of its wheel speeds (one signal: no "
                                      "matter)", choices="mean|min|max|first"),
        f"{name}_stale_after_s": _k(stale, f"s; the input is missing when no valid frame came for this long: it is "
                                           f"then reported and never guessed; {stale} s: {why_stale}",
                                    min=0.01, max=60.0),
    }
    if kind == "number":
        keys[f"{name}_unit"] = _k("dbc", f"unit of the decoded signal, converted to {si}; 'dbc' takes the "
                                         f"unit written in the DBC", choices=units)
        keys[f"{name}_scale"] = _k(1.0, "factor, no unit; applied after the unit conversion (tyre-size "
                                        "correction, sign convention); 1 = as decoded", min=-100.0, max=100.0)
        keys[f"{name}_offset"] = _k(0.0, f"{si}; added after scaling; 0 = as decoded", min=-100.0, max=100.0)
    else:
        keys[f"{name}_true_value"] = _k(-1, "raw value that means on (e.g. 1 for left in a turn-signal signal "
                                            "whose values are 1 left, 2 right); -1 = any non-zero value",
                                        min=-1, max=2**31 - 1)
    return keys


CAN_SCHEMA: dict[str, dict[str, dict]] = {
    "can": {
        "enabled": _k(True, "send Headway's frames (FCW, lead, objects, status) in `headway run`; on by default "
                            "because the status frame is the heartbeat other ECUs watch (replay writes them to "
                            "--can-out whatever this says)"),
        "interface": _k("virtual", "python-can interface; socketcan in the car (can0) or on a bench (vcan0); "
                                   "virtual (in-process, goes nowhere) by default so that Headway runs on any "
                                   "machine", choices=INTERFACES),
        "channel": _k("can0", "interface channel: can0/vcan0 for socketcan, /dev/ttyACM0 for slcan, any name "
                              "for virtual"),
        "bitrate": _k(500000, "bit/s; ignored by socketcan (set with `ip link`) and virtual; 500 kbit/s is the "
                              "usual powertrain/ADAS bus rate", min=10000, max=1000000),
        "receive_own_messages": _k(False, "python-can option: also receive the frames Headway sends (for "
                                          "loop-back tests); off because the inputs never come from Headway"),
        "input_channel": _k("", "channel of the vehicle bus the inputs come from when it is not `channel` "
                                "(same interface); empty = the same bus"),
        "id_base": _k(0x600, "CAN id of HW_FCW (1536 = 0x600); the other messages follow at +1 .. +6 in the "
                             "order of headway.dbc; the 0x6xx range is usually free of powertrain traffic",
                      min=0, max=0x7FF - 6),
        "fcw_rate_hz": _k(10.0, "Hz; HW_FCW is also sent at once on every change of level or availability; "
                                "10 Hz lets a receiver time out a lost Headway within 0.3 s", min=0.5, max=100.0),
        "lead_rate_hz": _k(10.0, "Hz; HW_LEAD and HW_LEAD_TTC; 0 = not sent; 10 Hz is every third frame at "
                                 "30 fps, plenty for display and logging", min=0.0, max=100.0),
        "objects_rate_hz": _k(10.0, "Hz; HW_OBJECT_HEADER and two HW_OBJECT frames per object; 0 = not sent",
                              min=0.0, max=100.0),
        "status_rate_hz": _k(10.0, "Hz; HW_STATUS heartbeat (state, fault bits); 10 Hz so that a receiver "
                                   "notices a silent Headway within a few hundred ms", min=0.5, max=100.0),
        "calibration_rate_hz": _k(1.0, "Hz; HW_CALIBRATION (the camera's pitch, yaw and height as self-calibration "
                                       "has them, their 1-sigma and state; two pages); 0 = not sent; 1 Hz because "
                                       "the estimate moves over seconds (it settles in 0.1-3 s, then drifts slowly)",
                                min=0.0, max=100.0),
        "max_objects": _k(16, "objects per object-list cycle (nearest first); 16 objects at 10 Hz make, "
                              "with the other messages, 370 frames/s: about 9 % of a 500 kbit/s bus", min=0, max=64),
        "data_timeout_s": _k(0.5, "s; FCW, lead and object frames never carry older results: past this age "
                                  "they go out as not available (a stalled core must not look like a quiet "
                                  "road)", min=0.05, max=10.0),
        "tx_error_hold_s": _k(1.0, "s; the can_error fault stays set this long after the last failed send, "
                                   "so a flapping bus is visible in the status frame", min=0.1, max=60.0),
        "output_log": _k("", "path; also write every frame Headway sends to this log (.log candump, .asc, "
                             ".blf); empty = none. The service never overwrites it: the previous run's log is "
                             "kept as NAME.1.SUFFIX (older ones .2, .3, ...)"),
        "output_log_keep": _k(10, "previous runs' output logs kept beside the current one (NAME.1 newest); the "
                                  "failing run's log is the one an engineer needs after a crash, 10 covers a day "
                                  "of restarts", min=1, max=1000),
        "output_log_sync_s": _k(0.5, "s; the output log is forced to the disk (fsync, off the frame loop) at least this often: a power "
                                     "cut loses at most this much (every batch reaches the OS at once, so a killed "
                                     "process loses nothing); 0 = after every batch", min=0.0, max=60.0),
    },
    "vehicle": {
        "dbc": _k("", "path; the car's DBC file (opendbc has most cars), used by every input without its "
                      "own *_dbc; empty = no vehicle inputs"),
        "channel": _k("", "only frames from this channel feed the inputs (e.g. can0 in a log that holds "
                          "several buses); empty = any channel"),
        "log_channels": _k("", "replay: the input log's channels as the bus's: 'any' takes every frame whatever its "
                               "channel (an .asc or .blf log numbers its channels 0, 1, ... where vehicle.channel "
                               "says can0), '0=can0,1=can1' maps them; empty = as recorded"),
        "log_offset_s": _k(0.0, "s; replay: the input CAN log's time since its first frame plus this is the "
                                "frame clock; 0 = the log and the video start together", min=-3600.0, max=3600.0),
    },
}
for _name in INPUTS:
    CAN_SCHEMA["vehicle"].update(_input_keys(_name))


def defaults() -> dict[str, dict]:
    """The CAN sections with every key at its default."""
    return {sec: {k: spec["default"] for k, spec in keys.items()} for sec, keys in CAN_SCHEMA.items()}


def with_defaults(cfg) -> dict:
    """``cfg`` with its ``can`` and ``vehicle`` sections completed from the defaults (a configuration
    loaded before these sections were registered, or a partial one in tests)."""
    out = dict(cfg)
    for sec, values in defaults().items():
        out[sec] = {**values, **dict(cfg.get(sec) or {})}
    return out
