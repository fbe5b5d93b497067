"""What the data can identify (:mod:`wresdyn.identify.identifiability`): a known-truth case where one effort limit and
one joint are deliberately unexcited, the JSON written, and the identify / fit commands' run folders."""

import dataclasses
import json

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.data.dataset import Dataset, Trajectory, derive_qdd
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.identifiability import identifiability, write_identifiability
from wresdyn.identify.unexcited_limits import demanded_torque
from wresdyn.identify.sysid_config import SysIdConfig
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.physics import PhysicalParams

REAL = Mismatch(kp_scale=0.8, kd_scale=1.3, friction=0.03, damping=0.3, delay=0.004)
STILL = "waist_yaw"
"""The joint whose command is held: it never moves."""
SMALL = SysIdConfig(fit=("kp", "effort"), horizon_curriculum=(32,), identifiability_windows=4)


@pytest.fixture(scope="module")
def still_data(humanoid):
    """Multisines on every joint but :data:`STILL` (its first command held), recorded on the real robot: 2 training
    and 1 validation trajectories of 0.3 s."""
    real, rate = RealRobot(humanoid, REAL, 500.0), 500.0
    j = humanoid.joint_names.index(STILL)
    trajs = []
    for k, split in enumerate(("train", "train", "validation")):
        cmd = multisine_command(humanoid, 0.3, 1.0 / rate, 0.3, seed=k)
        cmd[:, j] = cmd[0, j]
        q, qd, tau = real.record(cmd, np.random.default_rng(k))
        trajs.append(Trajectory(f"{split}_{k:03d}", split, np.arange(len(cmd)) / rate, q, qd, derive_qdd(qd, rate),
                                cmd, tau))
    return Dataset(list(humanoid.joint_names), rate, trajs, str(humanoid.source), humanoid.source_sha256,
                   REAL.to_dict(), 0, {"generator": "test_identifiability"})


def test_unexcited_limit_and_still_joint_are_flagged_and_excited_ones_are_not(humanoid, still_data, tmp_path):
    """The left knee's limit at 2 % of the file's saturates its drive all the time; the right knee's at 10x the
    file's is never reached: only the latter is flagged, and only its column of J is zero. The held joint is flagged
    still, a moving one is not."""
    params = PhysicalParams.nominal(humanoid)
    names = list(humanoid.joint_names)
    left, right = names.index("left_knee"), names.index("right_knee")
    params.effort[left] *= 0.02
    params.effort[right] *= 10.0
    found = identifiability(humanoid, still_data, params, SMALL)
    flags = {f["kind"]: f["parameters"] for f in found.flags}
    assert "effort:right_knee" in flags["unexcited_effort"]
    assert "effort:left_knee" not in flags["unexcited_effort"]
    assert STILL in flags["still_joint"] and "left_knee" not in flags["still_joint"]
    at = {n: i for i, n in enumerate(found.names)}
    assert found.sensitivity[at["effort:right_knee"]] == 0.0  # no replay saturates it: the loss does not see it
    assert found.sensitivity[at["effort:left_knee"]] > 0.0
    assert not np.isfinite(found.se[at["effort:right_knee"]])
    assert np.isfinite(found.se[at["kp:left_knee"]])
    # the held joint's gain shows far less than a moving, unsaturated joint's (here 9x the error)
    assert found.se_alone[at[f"kp:{STILL}"]] > 5 * found.se_alone[at["kp:right_knee"]]
    assert found.windows == 4 and found.steps == 32 and found.seconds > 0

    path = write_identifiability(tmp_path, found)
    data = json.loads(path.read_text())
    assert {"windows", "steps", "n_residuals", "sigma", "seconds", "parameters", "groups", "flags", "names",
            "correlation"} <= set(data)
    row = data["parameters"][at["kp:left_knee"]]
    assert {"name", "value", "coordinate", "sensitivity", "se_pct", "se", "se_alone"} <= set(row)
    assert row["coordinate"] == "relative" and row["se_pct"] == pytest.approx(100 * row["se"])
    assert len(data["correlation"]) == len(data["names"]) == len(found.names)
    assert all(f["advice"] for f in data["flags"])
    assert "--probe-saturation" in next(f["advice"] for f in data["flags"] if f["kind"] == "unexcited_effort")
    assert "What the data can identify" in (tmp_path / "identifiability.md").read_text()
    # the training data's demand: the never-saturated knee's is its largest demanded torque (the data's lower bound
    # on its limit), the always-saturated knee's stays at or below its limit; every fitted limited joint is listed
    demand, share = data["demanded_effort_nm"], data["effort_saturated"]
    tau = demanded_torque(params, still_data.split("train"), 1.0 / still_data.rate_hz)
    assert share["right_knee"] == 0.0 and demand["right_knee"] == pytest.approx(tau[:, right].max())
    assert demand["right_knee"] < params.effort[right]
    assert share["left_knee"] > 0.5 and 0 < demand["left_knee"] <= params.effort[left]
    assert set(demand) == set(share) == set(names) and data["effort_saturated_min"] == SMALL.saturated_min


def test_identify_and_fit_write_identifiability_in_their_run_folders(humanoid, still_data, tmp_path):
    """`wresdyn identify` writes identifiability.json beside physics.json and logs its flags (a resume may turn the
    report off); the hybrid `wresdyn fit` writes it in its identification's folder."""
    data = tmp_path / "d.npz"
    still_data.save(data)
    tiny = ["--windows", "2", "--identifiability-windows", "2"]
    run = tmp_path / "id"
    assert main(["identify", str(data), "--out", str(run), "--iterations", "4", "--horizon-curriculum", "8",
                 "--quiet", *tiny]) == 0
    found = json.loads((run / "identifiability.json").read_text())
    assert found["windows"] == 2 and found["steps"] == 8
    assert any(f["kind"] == "still_joint" and STILL in f["parameters"] for f in found["flags"])
    assert "identifiability:" in (run / "identify.log").read_text()
    assert main(["identify", str(data), "--out", str(run), "--iterations", "4", "--horizon-curriculum", "8",
                 "--quiet", "--no-identifiability", "--windows", "2"]) == 0  # resumed: the report may change
    fit = tmp_path / "fit"
    assert main(["fit", str(data), "--out", str(fit), "--iterations", "2", "--windows", "2", "--curriculum", "4",
                 "--identify.iterations", "2", "--identify.horizon-curriculum", "8",
                 "--identify.identifiability-windows", "2", "--quiet"]) == 0
    assert json.loads((fit / "identify" / "identifiability.json").read_text())["windows"] == 2
    assert "identifiability:" in (fit / "fit.log").read_text()


def test_the_report_is_configurable():
    assert SysIdConfig().identifiability and SysIdConfig().identifiability_windows == 16
    with pytest.raises(ValueError):
        dataclasses.replace(SysIdConfig(), identifiability_windows=0)
