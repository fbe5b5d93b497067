# Run from the repository root: PYTHONPATH=$PWD OMP_NUM_THREADS=1 python THIS DATA PHYSICS_JSON
"""Validation only: every torque (kp, kd, damping, friction, effort) and every inertia (armature, link masses and
inertias) of a fitted parameter set times s: motion is invariant if that is an exact symmetry."""
import sys, numpy as np
from wresdyn.data.loading import load_data
from wresdyn.identify.sysid import PhysicsScore
from wresdyn.sim.physics import PhysicalParams
ds, robot = load_data(sys.argv[1], None, None)
p = PhysicalParams.load(sys.argv[2], robot)
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, weights=ds.fit_weights())
for s in (1.0, 1 / 1.2, 1 / 1.1, 1.1):
    q = p.copy()
    for f in ("kp", "kd", "damping", "friction", "effort", "armature", "body_mass", "body_inertia"):
        setattr(q, f, getattr(p, f) * s)
    print(f"s = {s:.3f}: validation {score(q):.6f}")
