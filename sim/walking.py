"""Provides `walk` and `field_trials`: the study's hexapod walked in MuJoCo on a linkage leg,
the paper's Table I protocol (5 walks of 10 s per floor, the distance along the heading the
robot had at the start), with what a builder needs to trust the number.

A walk settles the robot on the floor for `settle_s` with the legs held at their phases,
then starts the gait's clock (`sim.gait.PhasePid`, the real robot's controller, ticking at
its `rate_hz`); each motor is its firmware velocity loop (`sim.robot.Motor`). Repeats differ by
a seeded perturbation of the start, as hand-placed trials do: heading within ±3°, position
within ±5 mm, each leg's phase within the alignment tolerance (±3°).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import statistics
from collections.abc import Iterator
from dataclasses import dataclass, field

import mujoco
import numpy as np

from linkevo.sim.gait import GaitConfig, PhasePid
from linkevo.sim.lean_model import LEAN_TIMESTEP_S, Coupling, build_lean_robot
from linkevo.sim.leg import Leg
from linkevo.sim.robot import LEG_SLOTS, TRIPOD_OFFSETS_DEG, WALK_SECONDS, Floor, Frame, Motor
from linkevo.sim.walk_model import TIMESTEP_S, RobotModel, build_robot

MODELS = {"lean": (build_lean_robot, LEAN_TIMESTEP_S), "full": (build_robot, TIMESTEP_S)}
"""The robot models a walk can run on, with their default physics steps: `lean` (each leg
reduced to the parts that meet the floor, `sim.lean_model`; the default) and `full` (every
beam a body, `sim.walk_model`; for pictures and cross-checks)."""

STALL_LAG_DEG = 45.0
"""A leg this far behind the clock with its motor at the supply limit has stalled."""
STALL_SATURATED = 0.05
"""... and its motor at the limit for at least this share of the walk."""
FRAME_DRAG_SHARE = 0.2
"""The frame touching the floor for more than this share of the walk: the legs cannot
carry it."""
PIN_FORCE_LIMIT_N = 60.0
"""The 99th-percentile pin force above which a LEGO Technic pin joint is taken to fail
(beams spread and the pin walks out); an estimate, see docs/walking.md."""
MIN_TIMESTEP_S = 0.0005
"""A walk that diverges is walked again at half the step, down to this one."""
LOOP_ERROR_BOUND_MM = 2.0
"""The loop-closure error a walk stays below at the default step (the tests hold it)."""
START_JITTER = {"heading_deg": 3.0, "position_mm": 5.0, "phase_deg": 3}


@dataclass(frozen=True)
class WalkSettings:
    """How a walk is simulated.

    Attributes:
        seconds: walking time after settling.
        settle_s: time on the floor with the legs held, before the clock starts.
        model: "lean" or "full" (`MODELS`).
        timestep: physics step (s); None for the model's own.
        loads_every: record pin loads and loop closure every this many control ticks.
        reverse: turn the cranks backwards (the gait's speed negated).
        sparse: solve the constraints with MuJoCo's sparse Jacobian instead of the dense
            one. The same walk to rounding (1e-12 m apart after 3 s on study legs), 1.3-1.5x
            faster on the lean model; walk maps use it, Table I's predictions are dense.
    """

    seconds: float = WALK_SECONDS
    settle_s: float = 0.5
    model: str = "lean"
    timestep: float | None = None
    loads_every: int = 2
    reverse: bool = False
    sparse: bool = False

    @property
    def step(self) -> float:
        """The physics step the walk runs at."""
        return self.timestep or MODELS[self.model][1]


@dataclass(frozen=True)
class Walk:
    """One simulated walk.

    Attributes:
        distance_m: displacement along the heading the robot had when the clock started.
        bound_m: the no-slip kinematic bound: twice the stance stroke per crank turn, over
            the turns the cranks made.
        heading_drift_deg: change of heading over the walk.
        body_height_m: mean height of the frame's centre; clearance_m: the least gap
            between the frame's underside and the floor (negative: it sank in).
        max_pitch_deg, max_roll_deg: the largest tilts.
        foot_slip_mm_s: mean horizontal speed of the feet while they are down.
        torque_p95, torque_max: motor torque over stall (95th percentile, largest).
        saturated: (6,) share of the walk each motor spent at its supply limit.
        max_lag_deg: the furthest any leg fell behind the clock.
        pin_force_n: 50th, 95th, 99th percentile and largest pin force (tree pins and
            loop closures) over the walk.
        loop_error_mm: the largest loop-closure error.
        frame_contact: share of the walk the frame touched the floor.
        breaks: the robot cannot walk as built; reason says why ("" when it walks).
        timestep: the physics step the walk ran at (a diverging walk is retried finer).
        diverged: the simulation blew up even at the finest step.
        trace: per control tick: "t" (T,), "body" (T, 3) frame position, "contact"
            (T, 6) bool each leg touching the floor, "phase" (T, 6) radians, "qpos"
            (T, nq) the whole state's positions (to replay the walk).
        model: the compiled robot the walk ran on (to replay or render it).
    """

    distance_m: float
    bound_m: float
    heading_drift_deg: float
    body_height_m: float
    clearance_m: float
    max_pitch_deg: float
    max_roll_deg: float
    foot_slip_mm_s: float
    torque_p95: float
    torque_max: float
    saturated: np.ndarray
    max_lag_deg: float
    pin_force_n: tuple[float, float, float, float]
    loop_error_mm: float
    frame_contact: float
    breaks: bool
    reason: str
    trace: dict[str, np.ndarray] = field(repr=False)
    timestep: float = TIMESTEP_S
    diverged: bool = False
    model: mujoco.MjModel | None = field(default=None, repr=False)


def walk(
    legs: Leg | dict[str, Leg],
    floor: Floor,
    *,
    gait: GaitConfig | None = None,
    offsets_deg: dict[str, float] | None = None,
    settings: WalkSettings | None = None,
    seed: int | None = None,
    frame: Frame | None = None,
    motor: Motor | None = None,
) -> Walk:
    """Walks the robot once and returns what happened.

    Args:
        legs: one leg for all six slots, or a leg per slot.
        floor: `sim.robot.FLOORS[name]`.
        gait: speed and PID (default: `configs/hexapod.toml`'s values).
        offsets_deg: each slot's phase offset in degrees (default: the study's tripods).
        settings: length, steps, direction.
        seed: the start's perturbation; None starts exactly at the offsets.
        frame, motor: the chassis and motor (defaults: the study's robot).
    """
    gait = gait or GaitConfig()
    settings = settings or WalkSettings()
    if settings.model not in MODELS:
        raise ValueError(f"robot model {settings.model!r}: allowed {', '.join(MODELS)}")
    motor = motor or Motor()
    offsets_deg = offsets_deg or TRIPOD_OFFSETS_DEG
    if isinstance(legs, Leg):
        legs = dict.fromkeys(LEG_SLOTS, legs)
    if settings.reverse:
        gait = dataclasses.replace(gait, speed_rpm=-gait.speed_rpm)
    offsets = np.radians([offsets_deg[s] for s in LEG_SLOTS])
    yaw, shift, jitter = 0.0, np.zeros(2), np.zeros(6)
    if seed is not None:
        rng = np.random.default_rng(seed)
        yaw = math.radians(rng.uniform(-1, 1) * START_JITTER["heading_deg"])
        shift = rng.uniform(-1, 1, 2) * START_JITTER["position_mm"] / 1000
        top = START_JITTER["phase_deg"]
        jitter = np.radians(rng.integers(-top, top + 1, 6))
    start = dict(zip(LEG_SLOTS, offsets + jitter, strict=True))
    build = MODELS[settings.model][0]
    while True:
        robot = build(legs, start, floor, frame=frame, motor=motor, timestep=settings.step)
        if settings.sparse:
            robot.model.opt.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE
        with _quiet_engine():
            result = _Run(robot, gait, motor, frame or Frame(), settings, offsets).run(yaw, shift)
        finer = settings.step / 2
        if not result.diverged or finer < MIN_TIMESTEP_S - 1e-12:
            return result
        # A stiff linkage can blow up at the default step: walk it again at half the step.
        settings = dataclasses.replace(settings, timestep=finer)


@contextlib.contextmanager
def _quiet_engine() -> Iterator[None]:
    """Keeps MuJoCo's warnings out of `MUJOCO_LOG.TXT` in the user's working directory.

    A walk reads the engine's warnings off `MjData.warning` (see `_Run._tick`) instead.
    """
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda _message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


class _Run:
    """One walk of a compiled robot: the control loop and the records it keeps."""

    def __init__(
        self,
        robot: RobotModel,
        gait: GaitConfig,
        motor: Motor,
        frame: Frame,
        settings: WalkSettings,
        offsets: np.ndarray,
    ) -> None:
        self.robot, self.gait, self.motor, self.settings = robot, gait, motor, settings
        self.frame, self.offsets = frame, offsets
        m = robot.model
        self.data = mujoco.MjData(m)
        self.tick_steps = max(1, round(1.0 / gait.rate_hz / settings.step))
        self.coupling: Coupling | None = robot.coupling  # type: ignore[assignment]
        body_leg = np.full(m.nbody, -1)
        for i, slot in enumerate(LEG_SLOTS):
            for b in range(m.nbody):
                if mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b).startswith(f"{slot}/"):
                    body_leg[b] = i
        self.geom_leg = body_leg[m.geom_bodyid]
        self.n_loops = len(robot.loop_pins)

    def run(self, yaw: float, shift: np.ndarray) -> Walk:
        m, d, robot = self.robot.model, self.data, self.robot
        d.qpos[0:2] += shift
        d.qpos[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        if self.coupling is not None:
            self.coupling.update(m, d)
        mujoco.mj_forward(m, d)
        hold = PhasePid(dataclasses.replace(self.gait, speed_rpm=0.0), self.offsets)
        hold.reset(0.0)
        n_settle = round(self.settings.settle_s * self.gait.rate_hz)
        for _ in range(n_settle):
            if not self._tick(hold):
                return self._diverged()
        pid = PhasePid(self.gait, self.offsets)
        pid.reset(d.time)
        p0, yaw0 = d.xpos[robot.frame_body].copy(), _yaw(d.xmat[robot.frame_body])
        self.phase0 = self.phases()
        n_ticks = round(self.settings.seconds * self.gait.rate_hz)
        rec = {k: [] for k in ("t", "body", "mat", "torque", "limits", "feet", "contact")}
        rec |= {"frame": [], "pins": [], "loops": [], "phase": [], "qpos": [], "poses": []}
        for tick in range(n_ticks):
            if not self._tick(pid):
                return self._diverged()
            self._record(rec, loads=tick % self.settings.loads_every == 0)
        return self._result(rec, pid, p0, yaw0)

    def phases(self) -> np.ndarray:
        return self.robot.start_phases + self.data.qpos[self.robot.crank_qpos]

    def _tick(self, pid: PhasePid) -> bool:
        """One control tick: the gait's command as the motors' speed goal, their torque
        limits at the speed they turn now, the lean model's couplings re-centred, then the
        physics over the tick."""
        m, d, motor, robot = self.robot.model, self.data, self.motor, self.robot
        rpm = np.clip(pid.rpm(d.time, self.phases()), -motor.velocity_limit_rpm,
                      motor.velocity_limit_rpm)  # fmt: skip
        d.ctrl[robot.actuators] = rpm * (2 * math.pi / 60)
        m.actuator_forcerange[robot.actuators] = motor.torque_limits(d.qvel[robot.crank_dof])
        if self.coupling is not None:
            self.coupling.update(m, d)
        mujoco.mj_step(m, d, nstep=self.tick_steps)
        # MuJoCo resets the state when accelerations blow up, and counts it as a warning.
        blown = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0
        return not blown and bool(np.isfinite(d.qpos).all()) and abs(d.qpos[2]) < 10.0

    def _record(self, rec: dict, loads: bool) -> None:
        """Keeps what the tick left: the state, the motors' torques and limits, contacts,
        and every `loads_every` ticks the loads (what needs the whole walk is computed
        from these at its end, `_result`)."""
        m, d, robot = self.robot.model, self.data, self.robot
        rec["t"].append(d.time)
        rec["body"].append(d.xpos[robot.frame_body].copy())
        rec["mat"].append(d.xmat[robot.frame_body].copy())
        rec["phase"].append(self.phases())
        rec["qpos"].append(d.qpos.copy())
        rec["torque"].append(d.actuator_force[robot.actuators])  # fancy indexing: a copy
        rec["limits"].append(m.actuator_forcerange[robot.actuators])
        rec["feet"].append(d.site_xpos[robot.foot_sites].copy())
        geoms = d.contact.geom[: d.ncon] if d.ncon else np.zeros((0, 2), dtype=int)
        touching = geoms.ravel()
        rec["frame"].append(bool((touching == robot.frame_geom).any()))
        legs = self.geom_leg[touching]
        contact = np.zeros(6, dtype=bool)
        contact[legs[legs >= 0]] = True
        rec["contact"].append(contact)
        if not loads:
            return
        if self.coupling is not None:
            n = len(self.coupling.equalities)  # equality rows come first, in id order
            rec["poses"].append(self.coupling.poses(d))
            rec["pins"].append(d.efc_force[:n].copy())
            rec["loops"].append(np.abs(d.efc_pos[:n]) * self.coupling.scale)
            return
        mujoco.mj_rnePostConstraint(m, d)
        tree = np.linalg.norm(d.cfrc_int[robot.leg_bodies, 3:], axis=1)
        rows = 3 * self.n_loops  # equality rows come first in the constraint arrays
        loops = np.linalg.norm(d.efc_force[:rows].reshape(-1, 3), axis=1)
        rec["pins"].append(np.concatenate([tree, loops]))
        rec["loops"].append(np.linalg.norm(d.efc_pos[:rows].reshape(-1, 3), axis=1))

    def _result(self, rec: dict, pid: PhasePid, p0: np.ndarray, yaw0: float) -> Walk:
        body, mats = np.array(rec["body"]), np.array(rec["mat"]).reshape(-1, 3, 3)
        t, phases = np.array(rec["t"]), np.array(rec["phase"])  # (T,), (T, 6)
        heading = np.array([math.cos(yaw0), math.sin(yaw0)])
        distance = float((body[-1, :2] - p0[:2]) @ heading)
        yaws = np.array([_yaw(x) for x in mats.reshape(-1, 9)])
        pitch = np.degrees(np.arcsin(np.clip(-mats[:, 2, 0], -1, 1)))
        roll = np.degrees(np.arctan2(mats[:, 2, 1], mats[:, 2, 2]))
        turned = phases[-1] - self.phase0  # (6,) radians each crank turned
        turns = float(np.abs(turned).mean()) / (2 * math.pi)
        bound = 2 * float(self.robot.stroke_m.mean()) * turns
        force, limits = np.array(rec["torque"]), np.array(rec["limits"])  # (T, 6), (T, 6, 2)
        torque = np.abs(force) / self.motor.stall_nm
        margin = 1e-3 * self.motor.stall_nm
        saturated = ((force <= limits[..., 0] + margin) | (force >= limits[..., 1] - margin)).mean(
            axis=0
        )
        sign = 1.0 if self.gait.speed_rpm >= 0 else -1.0
        errors = pid.errors(t[:, None], phases)  # (T, 6) the clock's lead on each leg
        lag = np.degrees(np.max(sign * errors, axis=0))  # behind the clock
        pins = np.concatenate(rec["pins"]) if self.coupling is None else self._statics(rec)
        percentiles = tuple(float(v) for v in np.percentile(pins, [50, 95, 99, 100]))
        loops = np.concatenate(rec["loops"]) if rec["loops"][0].size else np.zeros(1)
        frame_contact = float(np.mean(rec["frame"]))
        clearance = float(body[:, 2].min() - self.frame.height / 2)
        walk = Walk(
            distance_m=distance,
            bound_m=bound,
            heading_drift_deg=float(np.degrees(_wrap(yaws[-1] - yaw0))),
            body_height_m=float(body[:, 2].mean()),
            clearance_m=clearance,
            max_pitch_deg=float(np.abs(pitch).max()),
            max_roll_deg=float(np.abs(roll).max()),
            foot_slip_mm_s=_foot_slip(np.array(rec["feet"]), np.array(rec["contact"]), t),
            torque_p95=float(np.percentile(torque, 95)),
            torque_max=float(torque.max()),
            saturated=saturated,
            max_lag_deg=float(lag.max()),
            pin_force_n=percentiles,  # type: ignore[arg-type]
            loop_error_mm=float(loops.max() * 1000),
            frame_contact=frame_contact,
            breaks=False,
            reason="",
            trace={
                "t": t - t[0],
                "body": body,
                "contact": np.array(rec["contact"]),
                "phase": phases,
                "qpos": np.array(rec["qpos"]),
            },
            model=self.robot.model,
            timestep=self.settings.step,
        )
        reason = break_reason(walk, lag)
        return dataclasses.replace(walk, breaks=bool(reason), reason=reason)

    def _statics(self, rec: dict) -> np.ndarray:
        """Returns every pin's force at every recorded tick, all legs (the lean model's
        pins, from the statics of each leg's mechanism under its couplings' forces)."""
        coupling = self.coupling
        poses, forces = np.array(rec["poses"]), np.array(rec["pins"])  # (S, 6), (S, C)
        pins = []
        for statics in {id(s): s for s in coupling.statics}.values():  # legs alike: one solve
            slots = [i for i, s in enumerate(coupling.statics) if s is statics]
            wrench = np.concatenate(
                [forces[:, coupling.leg == i].reshape(len(forces), -1, 3) for i in slots]
            )  # (S * slots, K, 3): x, z, angle, in the frame's coordinates
            wrench = wrench * np.array([-statics.leg.facing(), 1.0, 1.0])  # linkage's frame
            pins.append(statics.pin_forces(poses[:, slots].T.ravel(), wrench).ravel())
        return np.concatenate(pins)

    def _diverged(self) -> Walk:
        nan = math.nan
        return Walk(
            nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, np.full(6, nan), nan,
            (nan, nan, nan, nan), nan, nan, True,
            "the simulation diverged (a loop flew apart): the linkage cannot be assembled "
            "as a rigid LEGO build",
            {},
            timestep=self.settings.step,
            diverged=True,
        )  # fmt: skip


def break_reason(walk: Walk, lag_deg: np.ndarray) -> str:
    """Returns why a walked robot breaks ("" when it does not): a stalled motor, a frame
    that drags, or pin loads above what a LEGO pin joint holds.

    Args:
        walk: the walk's figures.
        lag_deg: (6,) how far each leg fell behind the clock.
    """
    reasons = []
    stalled = (lag_deg > STALL_LAG_DEG) & (walk.saturated >= STALL_SATURATED)
    for i in np.flatnonzero(stalled):
        reasons.append(
            f"the {LEG_SLOTS[i]} motor stalls: at its torque limit for "
            f"{walk.saturated[i]:.0%} of the walk, the leg falls {lag_deg[i]:.0f}° behind "
            "the clock"
        )
    if walk.frame_contact > FRAME_DRAG_SHARE:
        reasons.append(
            f"the frame drags on the floor for {walk.frame_contact:.0%} of the walk: the "
            "legs cannot carry it"
        )
    if walk.pin_force_n[2] > PIN_FORCE_LIMIT_N:
        reasons.append(
            f"pin loads reach {walk.pin_force_n[2]:.0f} N (99th percentile), above the "
            f"{PIN_FORCE_LIMIT_N:.0f} N a LEGO Technic pin joint holds"
        )
    return "; ".join(reasons)


def field_trials(
    legs: Leg | dict[str, Leg],
    floor: Floor,
    *,
    repeats: int = 5,
    seed: int = 0,
    **kwargs,
) -> list[Walk]:
    """Returns `repeats` walks, repeat r perturbed by seed `seed * 1000 + r`; keyword
    arguments go to `walk`."""
    return [walk(legs, floor, seed=seed * 1000 + r, **kwargs) for r in range(repeats)]


def summary(walks: list[Walk], floor: Floor, seconds: float) -> dict:
    """Returns the JSON-able summary of field trials: distances in cm per repeat and their
    mean, and the builder's figures over the repeats (means, or the worst where a limit
    matters)."""

    def worst(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return max(finite) if finite else None

    def mean(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return statistics.fmean(finite) if finite else None

    distances = [w.distance_m * 100 for w in walks]
    broken = [w.reason for w in walks if w.breaks]
    reason = f"{broken[0]} ({len(broken)} of {len(walks)} walks break)" if broken else ""
    return {
        "floor": floor.name,
        "seconds": seconds,
        "distance_cm": [None if not math.isfinite(v) else round(v, 2) for v in distances],
        "mean_distance_cm": None if mean(distances) is None else round(mean(distances), 2),
        "bound_cm": None if mean(w.bound_m for w in walks) is None
        else round(mean(w.bound_m for w in walks) * 100, 2),
        "heading_drift_deg": [round(w.heading_drift_deg, 2) for w in walks],
        "beyond_bound": any(w.distance_m > w.bound_m for w in walks if math.isfinite(w.distance_m)),
        "breaks": any(w.breaks for w in walks),
        "reason": reason,
        "body_height_cm": _round(mean(w.body_height_m * 100 for w in walks)),
        "min_clearance_cm": _round(-worst(-w.clearance_m * 100 for w in walks)
                                   if worst(-w.clearance_m * 100 for w in walks) is not None
                                   else None),
        "max_pitch_deg": _round(worst(w.max_pitch_deg for w in walks)),
        "max_roll_deg": _round(worst(w.max_roll_deg for w in walks)),
        "foot_slip_mm_s": _round(mean(w.foot_slip_mm_s for w in walks)),
        "torque_p95_of_stall": _round(worst(w.torque_p95 for w in walks), 3),
        "torque_max_of_stall": _round(worst(w.torque_max for w in walks), 3),
        "max_lag_deg": _round(worst(w.max_lag_deg for w in walks)),
        "pin_force_p50_n": _round(mean(w.pin_force_n[0] for w in walks)),
        "pin_force_p95_n": _round(mean(w.pin_force_n[1] for w in walks)),
        "pin_force_p99_n": _round(worst(w.pin_force_n[2] for w in walks)),
        "pin_force_max_n": _round(worst(w.pin_force_n[3] for w in walks)),
        "loop_error_max_mm": _round(worst(w.loop_error_mm for w in walks), 3),
        "timestep_ms": [round(w.timestep * 1000, 3) for w in walks],
        "frame_contact_share": _round(worst(w.frame_contact for w in walks), 3),
    }  # fmt: skip


def _round(value: float | None, digits: int = 2) -> float | None:
    return None if value is None else round(float(value), digits)


def _yaw(mat: np.ndarray) -> float:
    return math.atan2(mat[3], mat[0])


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _foot_slip(feet: np.ndarray, contact: np.ndarray, t: np.ndarray) -> float:
    """Mean horizontal foot speed (mm/s) while a foot is down: its leg touches the floor
    and the foot is within 3 mm of the lowest height it reaches, over the feet (T, 6, 3)
    and contacts (T, 6) sampled at times t (T,)."""
    if len(t) < 2:
        return math.nan
    down = contact & (feet[:, :, 2] <= feet[:, :, 2].min(axis=0) + 0.003)
    both = down[1:] & down[:-1]
    dt = np.diff(t)[:, None]
    step = np.linalg.norm(np.diff(feet[:, :, :2], axis=0), axis=2) / np.where(dt > 0, dt, np.inf)
    return float(step[both].mean() * 1000) if both.any() else math.nan
