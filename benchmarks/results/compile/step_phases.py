"""The humanoid step's generated statements by phase (between codegen's outlining marks), for the parallel reverse
pass note in MANIFEST.md. usage, from the repository root: python benchmarks/results/compile/step_phases.py"""
import collections
import re

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay.codegen import _FLAT, _step_code
from wresdyn.sim.solver_replay.tree import tree_from_model

robot = load_robot("scenes/humanoid.usda")
tree = tree_from_model(robot.build_model(1, "cpu"))
params, loads, compute, stores = _step_code(tree, _FLAT, 8)
phase, count, flops = "prologue", collections.Counter(), collections.Counter()
names = [("kinematics", "FK, velocities, RNEA forward (root to leaves)"), ("RNEA and CRBA", "RNEA forces and CRBA (leaves to root)"),
         ("factorise", "L^T D L factorisation"), ("drive", "per-DoF drive, passive, limit terms"),
         ("solve", "triangular solves"), ("frictionless velocity", "v*"), ("friction sweep", "friction Gauss-Seidel sweeps"),
         ("friction result", "friction result"), ("semi-implicit Euler", "Euler")]
for line in compute:
    if line.startswith("#@"):
        for key, label in names:
            if key in line:
                phase = label
        continue
    count[phase] += 1
    flops[phase] += len(re.findall(r"[*+/-]", line.split(" = ", 1)[-1]))
tot, totf = sum(count.values()), sum(flops.values())
depth = [len(tree.ancestors(k)) for k in range(tree.n_dof)]
print(f"humanoid ({tree.n_dof} DoF, tree depth {max(depth) + 1}, {depth.count(0)} root DoFs): statements of one step by "
      "phase (codegen._step_code, 8 friction sweeps)")
for label, c in count.items():
    print(f"  {label:45s} {c:6d} statements ({100 * c / tot:4.1f} %), {flops[label]:6d} arithmetic operators "
          f"({100 * flops[label] / totf:4.1f} %)")
print(f"  total {tot} statements, {totf} operators; DoF depths: {sorted(collections.Counter(depth).items())}")
