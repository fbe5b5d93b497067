"""Solver set-up: the humanoid is stable at 500 Hz in Newton, and the explicit-PD criterion predicts divergence."""

import warnings

import numpy as np
import pytest

from wresdyn.robot.description import load_robot
from wresdyn.sim import SimulationDiverged, explicit_pd_margin, resolve_solver
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.rollout import replay

DT = 0.002


@pytest.mark.parametrize("solver", ["replay", "featherstone"])
def test_humanoid_stable_for_10s_excitation(humanoid, solver):
    assert explicit_pd_margin(humanoid, DT).max() < 0.5  # Featherstone's explicit PD is inside its region
    assert resolve_solver(humanoid, DT, "auto") == "replay"
    # large, fast multisine: 60 % of each joint's half-range, components up to 3 Hz
    cmd = multisine_command(humanoid, 10.0, DT, amplitude=0.6, seed=7)
    q, qd = replay(humanoid, cmd, cmd[0], dt=DT, solver=solver)
    assert np.isfinite(q).all() and np.isfinite(qd).all()
    assert np.abs(qd).max() < 50.0  # [rad/s] no runaway
    # PD follows the command: error well below the command's own motion (standing still scores 1.0;
    # low-gain arm joints lag a 3 Hz command, measured ratio ~0.66)
    assert np.abs(q[1:] - cmd).mean() < 0.8 * np.abs(cmd - cmd.mean(0)).mean()


def test_explicit_pd_criterion_predicts_featherstone_divergence():
    """newton issue 4269: high drive damping and no armature make explicit PD diverge at 500 Hz."""
    stiff = load_robot("newton:quadruped.urdf", gains={"joint": [{"match": "*", "kp": 100.0, "kd": 20.0, "armature": 0.0}]})
    assert explicit_pd_margin(stiff, DT).max() > 1.0
    cmd = multisine_command(stiff, 0.4, DT)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(SimulationDiverged):
            replay(stiff, cmd, cmd[0], dt=DT, solver="featherstone")
    # the implicit-PD solvers stay bounded on the same command: "auto" (SolverReplay on a fixed base), and
    # SolverMuJoCo, which "auto" picks on a floating base when the criterion fails
    assert resolve_solver(stiff, DT, "auto") == "replay"
    for solver in ("auto", "mujoco"):
        q, _ = replay(stiff, cmd, cmd[0], dt=DT, solver=solver)
        assert np.isfinite(q).all() and np.abs(q[1:] - cmd).max() < 0.5
    floating = load_robot("newton:quadruped.urdf", base="floating",
                          gains={"joint": [{"match": "*", "kp": 100.0, "kd": 20.0, "armature": 0.0}]})
    assert resolve_solver(floating, DT, "auto") == "mujoco"
