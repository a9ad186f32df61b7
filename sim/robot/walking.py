"""Provides `walk` and `field_trials`: the study's hexapod walked in MuJoCo on a linkage leg,
the paper's Table I protocol (5 walks of 10 s per floor, the distance along the heading the
robot had at the start), with what a builder needs to trust the number.

A walk settles the robot on the floor for `settle_s` with the legs held at their phases, then starts
the gait's clock (`sim.robot.gait.PhasePid`, the real robot's controller, ticking at its `rate_hz`);
each motor is its firmware velocity loop (`sim.robot.hexapod.Motor`). Repeats differ by a seeded
perturbation of the start, as hand-placed trials do: heading within ±3°, position within ±5 mm, each
leg's phase within the alignment tolerance (±3°).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import mujoco
import numpy as np

from linkevo.sim.robot.breaks import BreakWatch, break_reason, invalid_reason
from linkevo.sim.robot.frailty import Frailty, judge_frailty
from linkevo.sim.robot.full_model import TIMESTEP_S, build_robot
from linkevo.sim.robot.gait import GaitConfig, PhasePid
from linkevo.sim.robot.hexapod import (
    LEG_SLOTS,
    ROBOT_MODELS,
    TRIPOD_OFFSETS_DEG,
    WALK_SECONDS,
    Floor,
    Frame,
    Motor,
    Physics,
    Robot,
)
from linkevo.sim.robot.lean_model import LEAN_TIMESTEP_S, build_lean_robot
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.model import RobotModel, control_tick
from linkevo.sim.robot.mounting import Mounting, auto_spacers
from linkevo.sim.robot.walk_records import WalkRecords, foot_slip, wrap_angle, yaw_of

MODELS = dict(
    zip(ROBOT_MODELS, ((build_lean_robot, LEAN_TIMESTEP_S), (build_robot, TIMESTEP_S)), strict=True)
)
"""The robot models a walk can run on, with their default physics steps: `lean` (each leg
reduced to the parts that meet the floor, `sim.robot.lean_model`; the default) and `full` (every
beam a body, `sim.robot.full_model`; for pictures and cross-checks)."""

MIN_TIMESTEP_S = 0.0005
"""A walk that diverges is walked again at half the step, down to this one."""
LOOP_ERROR_BOUND_MM = 2.0
"""The loop-closure error a walk stays below at the default step (the tests hold it)."""
START_JITTER = {"heading_deg": 3.0, "position_mm": 5.0, "phase_deg": 3}
BREAK_CHECK_TICKS = 25
"""How often (control ticks, half a second) a walk that stops at its break checks."""


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
        stop_at_break: end the walk once the break rules are certain to call it broken
            (`sim.robot.breaks.BreakWatch`, checked every `BREAK_CHECK_TICKS`); its figures
            are then those of the stretch walked (the walking fitness's walks). A walk that
            does not break is the same walk either way.
    """

    seconds: float = WALK_SECONDS
    settle_s: float = 0.5
    model: str = "lean"
    timestep: float | None = None
    loads_every: int = 2
    reverse: bool = False
    sparse: bool = False
    stop_at_break: bool = False

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
        foot_deviation_mm: the furthest any foot strayed from where its linkage puts it at
            its crank's angle (`RobotModel.foot_deviation`): the pins' play along the leg.
        stopped_s: where a walk with `stop_at_break` ended because it had broken (seconds
            after the clock started), NaN when it ran its length.
        invalid: the model came apart (`sim.robot.breaks.invalid_reason`): the walk breaks
            with that reason and its distance is NaN, never a walk's.
        frailty: how far the real LEGO leg would give under the walk's loads
            (`sim.robot.frailty`; the frailest of the walked legs); a frail leg breaks the walk.
        spacers: each slot's spacer layers between the frame and its leg
            (`sim.robot.mounting`); legs that strike each other break the walk.
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
    foot_deviation_mm: float = math.nan
    stopped_s: float = math.nan
    frailty: Frailty | None = None
    invalid: bool = False
    spacers: dict[str, int] = field(default_factory=dict)


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
    physics: Physics | None = None,
    robot: Robot | None = None,
    spacers: dict[str, int] | None = None,
) -> Walk:
    """Walks the robot once and returns what happened.

    Args:
        legs: one leg for all six slots, or a leg per slot.
        floor: `sim.robot.hexapod.FLOORS[name]`.
        gait: speed and PID (default: `configs/hexapod.toml`'s values).
        offsets_deg: each slot's phase offset in degrees (default: the study's tripods).
        settings: length, steps, direction.
        seed: the start's perturbation; None starts exactly at the offsets.
        frame, motor: the chassis and motor (defaults: the study's robot).
        physics: a robot's own parameters (`sim.robot.hexapod.Physics`): its floor, frame and
            motor replace `floor`'s contact, `frame` and `motor`.
        robot: a robot whole (`sim.robot.hexapod.Robot`: its physics, gait, phases and
            mounting), in place of `physics`, `gait`, `offsets_deg` and `spacers`.
        spacers: each slot's spacer layers between the frame and its leg (default: chosen
            so that neighbouring legs cannot meet, `sim.robot.mounting.auto_spacers`).
    """
    if robot is not None:
        physics, gait, offsets_deg = robot.physics, robot.gait, robot.phases_deg
        spacers = robot.spacers
    if physics is not None:
        floor, frame, motor = physics.floor(floor.name), physics.frame(), physics.motor()
    frame = frame or Frame()
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
    if spacers is None:
        spacers = auto_spacers(legs, dict(zip(LEG_SLOTS, offsets, strict=True)), frame.leg_spacing)
    mounting = Mounting(legs, spacers, frame)
    build = MODELS[settings.model][0]
    while True:
        built = build(
            legs, start, floor, frame=frame, motor=motor, timestep=settings.step, spacers=spacers
        )
        if settings.sparse:
            built.model.opt.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE
        with quiet_engine():
            result = _Run(built, gait, motor, mounting, settings, offsets).run(yaw, shift)
        finer = settings.step / 2
        if not result.diverged or finer < MIN_TIMESTEP_S - 1e-12:
            return judge_frailty(result, mounting)
        # A stiff linkage can blow up at the default step: walk it again at half the step.
        settings = dataclasses.replace(settings, timestep=finer)


class _Run:
    """One walk of a compiled robot: the control loop and the records it keeps."""

    def __init__(
        self,
        robot: RobotModel,
        gait: GaitConfig,
        motor: Motor,
        mounting: Mounting,
        settings: WalkSettings,
        offsets: np.ndarray,
    ) -> None:
        self.robot, self.gait, self.motor, self.settings = robot, gait, motor, settings
        self.mounting, self.frame, self.offsets = mounting, mounting.frame, offsets
        m = robot.model
        self.data = mujoco.MjData(m)
        self.tick_steps = max(1, round(1.0 / gait.rate_hz / settings.step))
        body_leg = np.full(m.nbody, -1)
        for i, slot in enumerate(LEG_SLOTS):
            for b in range(m.nbody):
                if mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b).startswith(f"{slot}/"):
                    body_leg[b] = i
        self.geom_leg = body_leg[m.geom_bodyid]

    def run(self, yaw: float, shift: np.ndarray) -> Walk:
        m, d, robot = self.robot.model, self.data, self.robot
        d.qpos[0:2] += shift
        d.qpos[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        robot.loads.update(m, d)
        mujoco.mj_forward(m, d)
        hold = PhasePid(dataclasses.replace(self.gait, speed_rpm=0.0), self.offsets)
        hold.reset(0.0)
        n_settle = round(self.settings.settle_s * self.gait.rate_hz)
        for _ in range(n_settle):
            if not self._tick(hold):
                return self._diverged()
        pid = PhasePid(self.gait, self.offsets)
        pid.reset(d.time)
        p0, yaw0 = d.xpos[robot.frame_body].copy(), yaw_of(d.xmat[robot.frame_body])
        self.phase0 = self.phases()
        n_ticks = round(self.settings.seconds * self.gait.rate_hz)
        every = self.settings.loads_every
        samples = -(-n_ticks // every)
        rec = WalkRecords.empty(n_ticks, samples, m.nq, robot.loads.width)
        watch = BreakWatch(n_ticks, samples) if self.settings.stop_at_break else None
        for tick in range(n_ticks):
            if not self._tick(pid):
                return self._diverged()
            self._record(rec, tick)
            if tick % every == 0:
                robot.loads.sample(m, d, rec.loads[tick // every])
            done = tick + 1
            if watch and (done % BREAK_CHECK_TICKS == 0 or done == n_ticks):
                lag = functools.partial(self.lag_deg, pid)
                watch.follow(rec, done, -(-done // every), robot.loads.pin_forces, lag)
                if watch.broken() and done < n_ticks:
                    return self._result(rec.head(done, every), pid, p0, yaw0, watch.pins())
        return self._result(rec, pid, p0, yaw0, watch.pins() if watch else None)

    def phases(self) -> np.ndarray:
        return self.robot.start_phases + self.data.qpos[self.robot.crank_qpos]

    def _tick(self, pid: PhasePid) -> bool:
        """One control tick (`sim.robot.model.control_tick`): the gait's command as the
        motors' speed goal."""
        d, motor, robot = self.data, self.motor, self.robot
        rpm = np.clip(
            pid.rpm(d.time, self.phases()), -motor.velocity_limit_rpm, motor.velocity_limit_rpm
        )
        control_tick(robot, d, rpm * (2 * math.pi / 60), self.tick_steps)
        # MuJoCo resets the state when accelerations blow up, and counts it as a warning.
        blown = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0
        return not blown and bool(np.isfinite(d.qpos).all()) and abs(d.qpos[2]) < 10.0

    def _record(self, rec: WalkRecords, tick: int) -> None:
        """Keeps what the tick left: the state, the motors' torques and whether their
        drives are at the supply's limit, contacts (what needs the whole walk is computed
        from these at its end, `_result`)."""
        d, robot = self.data, self.robot
        rec.t[tick] = d.time
        rec.body[tick] = d.xpos[robot.frame_body]
        rec.mat[tick] = d.xmat[robot.frame_body]
        rec.phase[tick] = self.phases()
        rec.qpos[tick] = d.qpos
        rec.torque[tick] = robot.motor_torque(d)
        rec.limited[tick] = robot.at_supply_limit(d)
        rec.feet[tick] = d.site_xpos[robot.foot_sites]
        touching = d.contact.geom[: d.ncon].ravel() if d.ncon else np.zeros(0, dtype=int)
        rec.frame[tick] = bool((touching == robot.frame_geom).any())
        legs = self.geom_leg[touching]
        rec.contact[tick, legs[legs >= 0]] = True

    def lag_deg(self, pid: PhasePid, t: np.ndarray, phases: np.ndarray) -> np.ndarray:
        """Returns (6,) how far each leg fell behind the clock over ticks at t (T,) with
        phases (T, 6), in degrees."""
        sign = 1.0 if self.gait.speed_rpm >= 0 else -1.0
        return np.degrees(np.max(sign * pid.errors(t[:, None], phases), axis=0))

    def _result(
        self,
        rec: WalkRecords,
        pid: PhasePid,
        p0: np.ndarray,
        yaw0: float,
        pins: np.ndarray | None = None,
    ) -> Walk:
        """The walk's figures from its records (`pins`: the pin forces when already
        computed); a walk whose records end before its length stopped at its break."""
        body, mats = rec.body, rec.mat.reshape(-1, 3, 3)
        t, phases = rec.t, rec.phase  # (T,), (T, 6)
        heading = np.array([math.cos(yaw0), math.sin(yaw0)])
        distance = float((body[-1, :2] - p0[:2]) @ heading)
        yaws = np.array([yaw_of(x) for x in mats.reshape(-1, 9)])
        pitch = np.degrees(np.arcsin(np.clip(-mats[:, 2, 0], -1, 1)))
        roll = np.degrees(np.arctan2(mats[:, 2, 1], mats[:, 2, 2]))
        turned = phases[-1] - self.phase0  # (6,) radians each crank turned
        turns = float(np.abs(turned).mean()) / (2 * math.pi)
        bound = 2 * float(self.robot.stroke_m.mean()) * turns
        torque = np.abs(rec.torque) / self.motor.stall_nm  # (T, 6)
        saturated = rec.limited.mean(axis=0)
        lag = self.lag_deg(pid, t, phases)
        pins = self.robot.loads.pin_forces(rec.loads) if pins is None else pins
        percentiles = tuple(float(v) for v in np.percentile(pins, [50, 95, 99, 100]))
        loops = self.robot.loads.loop_errors(rec.loads)
        loops = loops if loops.size else np.zeros(1)
        deviation = self.robot.foot_deviation(phases, body, mats, rec.feet)
        frame_contact = float(np.mean(rec.frame))
        clearance = float(body[:, 2].min() - self.frame.height / 2)
        walk = Walk(
            distance_m=distance,
            bound_m=bound,
            heading_drift_deg=float(np.degrees(wrap_angle(yaws[-1] - yaw0))),
            body_height_m=float(body[:, 2].mean()),
            clearance_m=clearance,
            max_pitch_deg=float(np.abs(pitch).max()),
            max_roll_deg=float(np.abs(roll).max()),
            foot_slip_mm_s=foot_slip(rec.feet, rec.contact, t),
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
                "contact": rec.contact,
                "phase": phases,
                "qpos": rec.qpos,
            },
            model=self.robot.model,
            timestep=self.settings.step,
            foot_deviation_mm=float(deviation.max() * 1000),
            spacers=self.mounting.spacers,
        )
        invalid = invalid_reason(walk, self.settings.model, self.mounting.legs.values())
        if invalid:
            return dataclasses.replace(
                walk, distance_m=math.nan, breaks=True, reason=invalid, invalid=True
            )
        reason = "; ".join(
            r for r in (break_reason(walk, lag), self.mounting.strike(t, phases)) if r
        )
        planned = round(self.settings.seconds * self.gait.rate_hz)
        if len(t) < planned and reason:
            stopped = len(t) / self.gait.rate_hz
            reason += f" (stopped at {stopped:.1f} s of {self.settings.seconds:g})"
            walk = dataclasses.replace(walk, stopped_s=stopped)
        return dataclasses.replace(walk, breaks=bool(reason), reason=reason)

    def _diverged(self) -> Walk:
        nan = math.nan
        return Walk(
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            np.full(6, nan),
            nan,
            (nan, nan, nan, nan),
            nan,
            nan,
            True,
            "the simulation diverged (a loop flew apart): the linkage cannot be assembled "
            "as a rigid LEGO build",
            {},
            timestep=self.settings.step,
            diverged=True,
            spacers=self.mounting.spacers,
        )


@contextlib.contextmanager
def quiet_engine() -> Iterator[None]:
    """Keeps MuJoCo's warnings out of `MUJOCO_LOG.TXT` in the user's working directory.

    A walk reads the engine's warnings off `MjData.warning` (`sim.robot.walking`) instead.
    """
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda _message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


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
