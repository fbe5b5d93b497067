"""wresdyn: a Warp/Newton differentiable residual dynamics learner.

The package reads top to bottom in the order data flows:
robot -> excitation -> reference recording -> dataset -> replay sim -> residual model -> learners
(PPO, gradient) -> evaluation/report -> CLI. Heavy libraries (warp, newton, torch, mujoco, pinocchio,
pxr) are imported inside the modules that need them, so ``import wresdyn`` stays fast.
"""

__version__ = "0.1.0"

from .robot import DEFAULT_ROBOT, Robot, RobotError, load_robot

__all__ = ["DEFAULT_ROBOT", "Robot", "RobotError", "load_robot", "__version__"]
