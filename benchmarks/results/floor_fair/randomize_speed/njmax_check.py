"""The floor solver's contacts and constraint rows per world (``nconmax``, ``njmax``) as ``wresdyn/sim/solvers.py``
builds it for the floor (:func:`wresdyn.sim.solvers.floor_solver`, sized by :mod:`wresdyn.sim.floor_budget`), beside
Newton's own sizing of the model as built (the floor solver before that rule), on the CPU (2 worlds of the floor
humanoid, Newton's SolverMuJoCo on mujoco_warp), with what fills them.

Usage (repository root): python benchmarks/results/floor_fair/randomize_speed/njmax_check.py
"""

import newton
import numpy as np

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.robot.ground import ContactSettings
from wresdyn.sim.floor_budget import collision_shapes_newton, floor_budget
from wresdyn.sim.solvers import floor_solver

robot = load_robot(load_robot(DEFAULT_ROBOT).source, base="floating")
model = robot.build_model(2, "cpu", ground=True)
c = ContactSettings()
s = newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=False, disable_contacts=False, integrator="implicitfast",
                                solver=c.solver, cone=c.cone, iterations=c.iterations, ls_iterations=c.ls_iterations,
                                impratio=c.impratio, enable_multiccd=False)
print("Newton's sizing of the model as built: njmax", s.mjw_data.njmax, "naconmax", s.mjw_data.naconmax)
f = floor_solver(model)
print("floor_solver: njmax", f.mjw_data.njmax, "naconmax", f.mjw_data.naconmax, "(2 worlds)")
n = collision_shapes_newton(model)
print("collision shapes per world", n, "-> floor_budget(nconmax, njmax)", floor_budget(n, f.mjw_model.nv))
print("nv", s.mjw_model.nv, "ngeom", s.mjw_model.ngeom, "cone", c.cone,
      "condim max", int(np.max(s.mj_model.geom_condim)))
print("dof_frictionloss max (as built)", float(np.max(s.mjw_model.dof_frictionloss.numpy())))
print("limited joints", int(np.sum(s.mj_model.jnt_limited)))
