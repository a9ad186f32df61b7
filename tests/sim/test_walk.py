"""The 3-D walk on the real engine (MuJoCo): convergence, determinism, loop closure, the
kinematic bound, and the directions the docs predict (docs/walking.md)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from linkevo.sim import decode, simulate
from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.linkage.genome import random_genomes
from linkevo.sim.robot.hexapod import FLOORS, LEG_SLOTS, TRIPOD_OFFSETS_DEG, Frame, Motor
from linkevo.sim.robot.lean_model import build_lean_robot
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.robot.walking import LOOP_ERROR_BOUND_MM, WalkSettings, walk
from tests.helpers.walking import crank_leg, jansen_leg

SHORT = WalkSettings(seconds=4.0)
GRIPPY = dataclasses.replace(FLOORS["flat"], name="grippy", friction=1.5)
SLIPPERY = dataclasses.replace(FLOORS["flat"], name="slippery", friction=0.08)
SOFT = dataclasses.replace(FLOORS["flat"], name="soft", solref=(0.03, 1.0), solimp=(0.3, 0.9, 0.01))


@pytest.fixture(scope="module")
def jansen():
    return jansen_leg()


@pytest.fixture(scope="module")
def evolved():
    """The best-F_p linkage of 3,000 random genomes that turns a full turn: a leg from the
    genome path (LEGO build, layers, rigid parts) as `linkevo pull` builds it."""
    genomes = random_genomes(np.random.default_rng(7), 3000)
    loss = evaluate(genomes, "Fp", "paper").loss
    for i in np.argsort(loss):
        try:
            return leg_from_genome(genomes[i])
        except LegError:
            continue
    raise AssertionError("no random genome turns a full turn")


def test_halving_the_timestep_changes_the_distance_by_less_than_5_percent(jansen, evolved):
    for leg in (jansen, evolved):
        coarse = walk(leg, FLOORS["carpet"], settings=SHORT)
        fine = walk(leg, FLOORS["carpet"], settings=dataclasses.replace(SHORT, timestep=0.0005))
        assert abs(coarse.distance_m) > 0.05
        assert abs(coarse.distance_m - fine.distance_m) < 0.05 * abs(fine.distance_m)


def test_the_same_seed_gives_the_same_distance_and_another_seed_another(evolved):
    first = walk(evolved, FLOORS["flat"], settings=SHORT, seed=3)
    again = walk(evolved, FLOORS["flat"], settings=SHORT, seed=3)
    other = walk(evolved, FLOORS["flat"], settings=SHORT, seed=4)
    assert first.distance_m == again.distance_m
    assert first.heading_drift_deg == again.heading_drift_deg
    assert other.distance_m != first.distance_m


def test_the_sparse_jacobian_walks_as_the_dense_one(evolved):
    dense = walk(evolved, FLOORS["flat"], settings=SHORT)
    sparse = walk(evolved, FLOORS["flat"], settings=dataclasses.replace(SHORT, sparse=True))
    assert sparse.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
    assert dense.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_DENSE
    assert sparse.distance_m == pytest.approx(dense.distance_m, abs=1e-6)
    assert sparse.pin_force_n[2] == pytest.approx(dense.pin_force_n[2], rel=1e-6)
    assert sparse.breaks == dense.breaks


@pytest.mark.parametrize("model", ["lean", "full"])
@pytest.mark.parametrize("floor", ["flat", "carpet"])
def test_loops_stay_closed_and_no_walk_beats_the_no_slip_bound(jansen, evolved, floor, model):
    for leg in (jansen, evolved):
        w = walk(leg, FLOORS[floor], settings=dataclasses.replace(SHORT, model=model))
        assert 0 < w.loop_error_mm < LOOP_ERROR_BOUND_MM
        assert 0 < w.distance_m <= w.bound_m


@pytest.mark.parametrize("floor", ["flat", "carpet"])
def test_the_lean_model_walks_as_the_full_one(jansen, evolved, floor):
    """The lean model (legs reduced to the parts that meet the floor) against the full one
    (every beam a body): distance within 10 %, the builder's loads within 25 %."""
    for leg in (jansen, evolved):
        lean = walk(leg, FLOORS[floor], settings=SHORT)
        full = walk(leg, FLOORS[floor], settings=dataclasses.replace(SHORT, model="full"))
        assert abs(lean.distance_m - full.distance_m) < 0.1 * abs(full.distance_m)
        assert abs(lean.pin_force_n[2] - full.pin_force_n[2]) < 0.25 * full.pin_force_n[2]
        assert abs(lean.torque_p95 - full.torque_p95) < 0.25 * full.torque_p95
        assert lean.breaks == full.breaks


def test_the_lean_pin_statics_balance_the_motor_as_the_physics_does(evolved):
    """The motor torque the statics of the massless leg needs under the couplings' forces is
    the torque those couplings put on the crank in MuJoCo (to the poses' 1° rounding)."""
    phases = {s: np.radians(TRIPOD_OFFSETS_DEG[s]) for s in LEG_SLOTS}
    legs = dict.fromkeys(LEG_SLOTS, evolved)
    robot = build_lean_robot(legs, phases, FLOORS["carpet"], frame=Frame(mass_kg=5.0))
    model, coupling = robot.model, robot.loads
    data = mujoco.MjData(model)
    data.ctrl[:] = 2.6  # rad/s, about the gait's speed
    statics, facing = coupling.statics[0], evolved.facing()
    torques, balanced = [], []
    for tick in range(100):
        coupling.update(model, data)
        mujoco.mj_step(model, data, nstep=10)
        if tick % 10 == 9:
            forces = data.efc_force[: len(coupling.equalities)][coupling.leg == 0]
            wrench = forces.reshape(1, -1, 3) * np.array([-facing, 1.0, 1.0])
            torques.append(statics.solve(coupling.poses(data)[:1], wrench)[1][0])
            balanced.append(-data.qfrc_constraint[robot.crank_dof[0]])
    torques, balanced = np.array(torques), np.array(balanced)
    assert np.abs(balanced).max() > 0.05  # N·m: the legs carry a 5 kg frame
    assert np.abs(torques - balanced).max() < 0.05 * np.abs(balanced).max()


def test_a_grippy_floor_cannot_push_a_walk_past_the_bound(evolved):
    w = walk(evolved, GRIPPY, settings=SHORT)
    assert 0 < w.distance_m <= w.bound_m


def test_a_leg_whose_foot_never_reaches_the_floor_goes_nowhere():
    frame = Frame()
    short = crank_leg(length=1.5)  # 12 mm + a beam's half width, inside the 25 mm half-height
    assert short.paths[:, :, 1].min() * 8 + 3.6 < frame.height / 2 * 1000
    w = walk(short, FLOORS["flat"], settings=SHORT)
    assert abs(w.distance_m) < 0.002
    assert w.breaks and "frame drags" in w.reason


def test_a_leg_whose_foot_is_a_bare_frame_hole_walks_on_both_models_credited_nothing():
    """The lowest point of a linkage can be a frame hole no beam holds (a few in 20,000 random
    linkages, more among a walking search's candidates): both models walk it with the foot
    on the frame, and its level-body bound, so all a walk is credited, is nothing."""
    genomes = random_genomes(np.random.default_rng(2), 1000)
    batch = decode(genomes)
    motion = simulate(batch, 40)
    bare = [
        i
        for i in np.flatnonzero(motion.error == 0)
        if motion.foot[i] not in batch.beam_int[i, : batch.n_beams[i], :2]
    ]
    leg = leg_from_genome(genomes[bare[0]])
    for model in ("lean", "full"):
        w = walk(leg, FLOORS["flat"], settings=dataclasses.replace(SHORT, model=model))
        assert w.bound_m == 0.0 and np.isfinite(w.distance_m)


def test_cranks_turned_backwards_walk_backwards(jansen):
    forward = walk(jansen, FLOORS["flat"], settings=SHORT)
    backward = walk(jansen, FLOORS["flat"], settings=dataclasses.replace(SHORT, reverse=True))
    assert forward.distance_m > 0.1
    assert backward.distance_m < -0.5 * forward.distance_m


def test_more_friction_means_less_slip_and_a_flat_stance_walks_further(jansen, evolved):
    for leg in (jansen, evolved):
        slippery = walk(leg, SLIPPERY, settings=SHORT)
        grippy = walk(leg, GRIPPY, settings=SHORT)
        assert grippy.foot_slip_mm_s < slippery.foot_slip_mm_s
    # A flat stance moves every down foot alike, so grip only removes slip (docs/walking.md)
    assert (
        walk(jansen, GRIPPY, settings=SHORT).distance_m
        > walk(jansen, SLIPPERY, settings=SHORT).distance_m
    )


def test_a_softer_floor_walks_less_far_and_the_feet_sink_in(jansen, evolved):
    for leg in (jansen, evolved):
        stiff = walk(leg, FLOORS["flat"], settings=SHORT)
        soft = walk(leg, SOFT, settings=SHORT)
        assert soft.distance_m < stiff.distance_m
        assert soft.body_height_m < stiff.body_height_m


def test_a_flat_stance_walks_close_to_its_kinematic_bound(jansen):
    w = walk(jansen, GRIPPY, settings=SHORT)
    assert 0.9 * w.bound_m <= w.distance_m <= w.bound_m
    assert not w.breaks


def test_a_motor_too_weak_for_the_robot_stalls_and_the_walk_breaks(evolved):
    weak = walk(evolved, FLOORS["flat"], settings=SHORT, motor=Motor(stall_nm=0.02))
    assert weak.breaks and "motor stalls" in weak.reason
    assert weak.max_lag_deg > 45
    assert not walk(evolved, FLOORS["flat"], settings=SHORT).breaks


def test_a_frame_too_heavy_for_lego_pins_breaks_on_pin_loads(jansen):
    heavy = walk(jansen, FLOORS["flat"], settings=SHORT, frame=Frame(mass_kg=40.0))
    assert heavy.pin_force_n[2] > 60.0
    assert heavy.breaks and "pin loads" in heavy.reason


def test_linkevo_sim_walks_a_robot_from_a_document_as_a_notebook_would():
    """`from linkevo.sim import ...` gives the walking functions, never a module they
    share a name with, and walks a robot from a linkage document."""
    import json
    import types
    from pathlib import Path

    import linkevo.sim as sim

    doc = json.loads((Path(__file__).parents[1] / "data" / "sound_leg.json").read_text())
    from linkevo.sim import FLOORS, WalkSettings, from_document, leg_from_genome
    from linkevo.sim import walk as walk_fn

    assert not any(isinstance(getattr(sim, name), types.ModuleType) for name in sim.__all__)
    result = walk_fn(
        leg_from_genome(*from_document(doc)), FLOORS["flat"], settings=WalkSettings(seconds=1.0)
    )
    assert result.distance_m > 0.01 and not result.breaks


@pytest.mark.parametrize("model", ["lean", "full"])
def test_a_braked_crank_turns_on_the_datasheet_line_through_the_walks_control_tick(evolved, model):
    """Each crank braked by a constant torque, the motors driven through the walk's own
    control tick (`control_tick`, every 20 ms) at their velocity limit: the speed they
    settle at lies within 5 % of the MX-28's torque-speed line at that load. The robot
    hangs in the air (no gravity, its frame held still at every tick), so the brake is the
    load."""
    from linkevo.sim.robot.model import control_tick
    from linkevo.sim.robot.walking import MODELS

    motor = Motor()
    build, step = MODELS[model]
    phases = {s: np.radians(TRIPOD_OFFSETS_DEG[s]) for s in LEG_SLOTS}
    for load in (0.5, 1.25, 1.8):
        robot = build(dict.fromkeys(LEG_SLOTS, evolved), phases, FLOORS["flat"], timestep=step)
        robot.model.opt.gravity[:] = 0.0
        data = mujoco.MjData(robot.model)
        data.qpos[2] += 1.0  # off the floor
        held = data.qpos[:7].copy()
        goal = np.full(6, motor.velocity_limit_rpm * 2 * np.pi / 60)
        speeds = []
        for tick in range(150):  # 3 s: 1.5 s to settle, 1.5 s measured
            data.qfrc_applied[robot.crank_dof] = -load
            control_tick(robot, data, goal, round(0.02 / step))
            data.qpos[:7], data.qvel[:6] = held, 0.0
            if tick >= 75:
                speeds.append(data.qvel[robot.crank_dof].copy())
        expected = float(motor.speed_at(load))
        measured = np.mean(speeds, axis=0)  # (6,) each crank's mean speed
        assert np.all(np.abs(measured - expected) <= 0.05 * expected), (load, measured, expected)
