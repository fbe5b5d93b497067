# Run from the repository root: PYTHONPATH=$PWD OMP_NUM_THREADS=1 python THIS DATA PHYSICS_JSON
"""Validation only: refine_all's fitted parameters with the delay replaced (all joints) by 0..4 samples."""
import sys, time, numpy as np
from wresdyn.data.loading import load_data
from wresdyn.identify.sysid import PhysicsScore
from wresdyn.sim.physics import PhysicalParams
data, phys = sys.argv[1], sys.argv[2]
ds, robot = load_data(data, None, None)
p = PhysicalParams.load(phys, robot)
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, weights=ds.fit_weights())
dt = 1.0 / ds.rate_hz
t0 = time.time()
print("as fitted (delay/dt:", np.round(p.delay / dt, 2).tolist(), "):", f"{score(p):.6f}")
for d in (0, 1, 2, 3, 4, 5):
    q = p.copy(); q.delay = np.full(robot.n_dof, d * dt)
    print(f"all joints at {d} samples: {score(q):.6f}")
print(f"{time.time() - t0:.0f} s")
