import numpy as np
from wresdyn.data.loading import load_data
from wresdyn.sim import replay_trajectories

dataset, robot = load_data("data/dataset.npz")            # the recordings and the robot they were made on
validation = dataset.split("validation")                   # 4 trajectories of 4 s at 500 Hz
pd = replay_trajectories(robot, validation, dataset.rate_hz)["pd"]   # Newton replay, PD only, open loop
err = np.mean([np.abs(q - tr.q).mean() for q, tr in zip(pd.q, validation)])
print(f"{robot.n_dof} joints, PD-only mean |dq| on validation: {err:.4f} rad")
