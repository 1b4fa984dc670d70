"""Kinematics of the scenario world: ego, vehicles, camera shake, collision.

Every quantity is a closed-form function of time: longitudinal motion integrates
piecewise-constant acceleration exactly (speeds stop at their target or at 0), lane changes
follow a half-cosine lateral profile. So any frame can be evaluated on its own (tests render
frames spread through a run without stepping through the rest) and the CAN log can sample the
ego speed at 50 Hz from the same motion the frames use.

Coordinates: X right of the ego-lane centre, Z forward. The ego keeps to its lane centre;
``odometer_m`` is how far it has driven. Vehicle ``z_m`` is the rear face relative to the
camera, as in the scenario file and the ground truth.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from .scenario import KMH, LaneChange, Scenario, ScenarioError, SpeedStep, VehicleSpec


class Motion1D:
    """Position and speed under piecewise-constant acceleration, exact at any time."""

    def __init__(self, z0_m: float, speed0_mps: float, steps: Sequence[SpeedStep]):
        commands = [(s.t_s, s.accel_mps2, None if s.until_speed_kmh is None else s.until_speed_kmh * KMH)
                    for s in steps]
        if not commands or commands[0][0] > 0.0:
            commands.insert(0, (0.0, 0.0, None))
        t0s, v0s, accels = [], [], []
        v = speed0_mps
        for i, (t0, a, target) in enumerate(commands):
            t_next = commands[i + 1][0] if i + 1 < len(commands) else math.inf
            # Braking without a target stops at 0; speeds never go negative (no reversing).
            limit = target if target is not None else (0.0 if a < 0 else math.inf)
            if a < 0:
                limit = max(limit, 0.0)
            if a == 0 or (a > 0 and v >= limit) or (a < 0 and v <= limit):
                t0s.append(t0), v0s.append(v), accels.append(0.0)
                continue
            t_hit = t0 + (limit - v) / a
            t0s.append(t0), v0s.append(v), accels.append(a)
            if t_hit < t_next:
                t0s.append(t_hit), v0s.append(limit), accels.append(0.0)
                v = limit
            else:
                v = v + a * (t_next - t0)
        self.t0 = np.array(t0s)
        self.v0 = np.array(v0s)
        self.a = np.array(accels)
        # Position at each segment start: z += v dt + a dt^2 / 2 over the previous segment.
        dt = np.diff(self.t0)
        self.z0 = z0_m + np.concatenate([[0.0], np.cumsum(self.v0[:-1] * dt + 0.5 * self.a[:-1] * dt * dt)])

    def at(self, t_s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position m, speed m/s, acceleration m/s^2) at time(s) ``t_s`` >= 0."""
        t = np.asarray(t_s, dtype=np.float64)
        k = np.searchsorted(self.t0, t, side="right") - 1
        dt = t - self.t0[k]
        return self.z0[k] + self.v0[k] * dt + 0.5 * self.a[k] * dt * dt, self.v0[k] + self.a[k] * dt, self.a[k]


class LateralMotion:
    """Lateral position of a vehicle centre (m, world X) through its lane changes (the ego's too: lane 0)."""

    def __init__(self, lane: int, offset_m: float, changes: Sequence[LaneChange], lane_width_m: float):
        self.x0 = lane * lane_width_m + offset_m
        self.moves = []
        for change in changes:
            self.moves.append((change.t_s, change.duration_s, (change.to_lane - lane) * lane_width_m))
            lane = change.to_lane

    def at(self, t_s: float | np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        x = np.full(t.shape, self.x0)
        for t0, duration, dx in self.moves:
            # Half-cosine blend: zero lateral speed at the start and end of the manoeuvre.
            tau = np.clip((t - t0) / duration, 0.0, 1.0)
            x = x + dx * 0.5 * (1.0 - np.cos(math.pi * tau))
        return x

    def speed(self, t_s: float) -> float:
        """Lateral speed (m/s) at time t_s: the derivative of the half-cosine blends."""
        v = 0.0
        for t0, duration, dx in self.moves:
            tau = (t_s - t0) / duration
            if 0.0 < tau < 1.0:
                v += dx * 0.5 * math.pi / duration * math.sin(math.pi * tau)
        return v


@dataclasses.dataclass(frozen=True)
class VehicleState:
    spec: VehicleSpec
    x_m: float  # centre of the rear face, world X (right of the ego-lane centre)
    z_m: float  # rear face ahead of the camera
    speed_mps: float
    accel_mps2: float
    relative_speed_mps: float  # dz/dt, negative when closing


@dataclasses.dataclass(frozen=True)
class WorldState:
    t_s: float
    ego_speed_mps: float
    ego_odometer_m: float
    vehicles: tuple[VehicleState, ...]


class World:
    """The scenario's motion, evaluated at frame times."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.ego = Motion1D(0.0, scenario.ego.speed_kmh * KMH, scenario.ego.profile)
        self.longitudinal = [Motion1D(v.z_m, v.speed_kmh * KMH, v.profile) for v in scenario.vehicles]
        self.lateral = [LateralMotion(v.lane, v.lateral_offset_m, v.lane_changes, scenario.road.lane_width_m)
                        for v in scenario.vehicles]
        self.ego_lateral = LateralMotion(0, 0.0, scenario.ego.lane_changes, scenario.road.lane_width_m)
        nominal = max(1, scenario.n_frames_nominal)
        self.times_s = np.arange(nominal) / scenario.fps
        self.collision_frame = self._check_motion()
        self.n_frames = nominal if self.collision_frame is None else self.collision_frame
        self.pitch_shake_deg, self.yaw_shake_deg = self._shake(nominal)

    def state(self, t_s: float) -> WorldState:
        odometer_m, ego_speed_mps, _ = self.ego.at(t_s)
        vehicles = []
        for spec, lon, lat in zip(self.scenario.vehicles, self.longitudinal, self.lateral):
            z_world, speed, accel = lon.at(t_s)
            vehicles.append(VehicleState(spec, float(lat.at(t_s)), float(z_world - odometer_m), float(speed),
                                         float(accel), float(speed - ego_speed_mps)))
        return WorldState(float(t_s), float(ego_speed_mps), float(odometer_m), tuple(vehicles))

    def frame_state(self, index: int) -> WorldState:
        return self.state(index / self.scenario.fps)

    # --- physical consistency -------------------------------------------------------------------
    def _check_motion(self) -> int | None:
        """First frame at which the ego has run into a vehicle ahead, or None.

        Any other overlap of bodies (vehicle into vehicle, a vehicle into the ego's side or
        rear) makes the scenario impossible: ScenarioError naming both.
        """
        s = self.scenario
        t = self.times_s
        ego_odo, _, _ = self.ego.at(t)
        x = [lat.at(t) for lat in self.lateral]
        ego_x = self.ego_lateral.at(t)  # the ego's own lane changes (0 without)
        z = [lon.at(t)[0] - ego_odo for lon in self.longitudinal]
        where = s.label
        # Ego body: from front_m - length_m to front_m in camera Z, centred on X = 0.
        ego_rear_m = s.ego.front_m - s.ego.length_m
        collision = None
        for i, v in enumerate(s.vehicles):
            side = np.abs(x[i] - ego_x) < 0.5 * (v.width_m + s.ego.width_m)
            touching = side & (z[i] <= s.ego.front_m) & (z[i] + v.length_m > ego_rear_m)
            if touching.any():
                k = int(np.argmax(touching))
                # A frontal collision is the rear face crossing the ego front from ahead.
                if k == 0 or not (side[k - 1] and z[i][k - 1] > s.ego.front_m):
                    raise ScenarioError(f"{where}: vehicles[{i}] (id {v.id}) overlaps the ego vehicle at "
                                        f"t={t[k]:.2f} s (lateral {x[i][k]:.2f} m, z {z[i][k]:.2f} m)")
                collision = k if collision is None else min(collision, k)
        end = len(t) if collision is None else collision
        for i, a in enumerate(s.vehicles):
            for j in range(i + 1, len(s.vehicles)):
                b = s.vehicles[j]
                hit = ((np.abs(x[i] - x[j]) < 0.5 * (a.width_m + b.width_m))
                       & (z[i] < z[j] + b.length_m) & (z[j] < z[i] + a.length_m))[:end]
                if hit.any():
                    k = int(np.argmax(hit))
                    raise ScenarioError(f"{where}: vehicles[{i}] (id {a.id}) and vehicles[{j}] (id {b.id}) "
                                        f"overlap at t={t[k]:.2f} s (z {z[i][k]:.1f} m and {z[j][k]:.1f} m)")
        return collision

    # --- camera shake ---------------------------------------------------------------------------
    def _shake(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame pitch/yaw offsets (deg): two road-induced sinusoids plus smoothed noise.

        Amplitudes follow the scenario; shake grows with speed (a stopped car barely moves).
        """
        s = self.scenario
        rng = np.random.default_rng([s.seed, 0x5AC])
        t = self.times_s[:n]
        _, speed, _ = self.ego.at(t)
        gain = 0.3 + 0.7 * np.minimum(1.0, speed / 25.0)
        out = []
        for amplitude, freqs in ((s.shake.pitch_deg, (1.6, 3.7)), (s.shake.yaw_deg, (0.7, 2.3))):
            phases = rng.uniform(0.0, 2.0 * math.pi, size=2)
            noise = np.empty(n)
            level = 0.0
            for k, e in enumerate(rng.standard_normal(n)):
                level = 0.8 * level + 0.6 * e  # AR(1): stationary std 1, correlated over ~5 frames
                noise[k] = level
            wave = (0.5 * np.sin(2 * math.pi * freqs[0] * t + phases[0])
                    + 0.3 * np.sin(2 * math.pi * freqs[1] * t + phases[1]) + 0.2 * noise)
            out.append(amplitude * gain * wave)
        return out[0], out[1]
