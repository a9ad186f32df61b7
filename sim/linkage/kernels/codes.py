"""Provides the kernels' constants: the published tolerances and limits, the node, beam and
fitness codes of the packed topology tables (`sim.linkage.decoding` documents their layout)."""

from __future__ import annotations

import numpy as np

TOL = 0.1
"""The tolerance of circle_intersection (spec §2), as published."""
L_MAX = 15.0
L_MIN = 2.0
EXACT = 1e-9
"""Largest beam stretch (modules) of a whole-module rounding that counts as exact
kinematics, a rigid beam (`sim.robot.lego`, `kernels.rounding`)."""
MAX_ANCHOR_DIST = 30.0
MIN_ANCHOR_DIST = 0.1
BAND = 0.5
"""F_sl contact band above the lowest sample."""
NAN_OR_ONE = np.array([np.nan, 1.0])
"""A failed (0) sample's foot position times NaN is NaN, a recorded (1) one's times 1 is
itself, bit for bit (foot_path)."""

# Node kinds (column 0 of the node table) and beam kinds.
MOTOR, STATIC, CRANK, TRIANGLE, EXTENSION = 0, 1, 2, 3, 4
B_CRANK, B_TRIANGLE, B_EXTENSION = 0, 1, 2
CRANK_TIP = 4

# Fitness codes.
FP, FSL, FP2, FSL2 = 0, 1, 2, 3
