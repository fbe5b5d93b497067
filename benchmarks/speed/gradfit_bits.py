"""SHA-256 digests of what a few gradient-fit iterations compute on the CPU, both paths (plain and
``GradFitConfig.fused_network``): one window batch's rollout (q, q̇, actions), its loss and the parameters' gradients
before the clip, then each iteration's loss parts and the weights after them. Two versions of the code that print the
same lines compute the same results bit for bit (a speed change that must not change them).

    python benchmarks/speed/gradfit_bits.py --windows 8

The shipped humanoid (21 DoF) and data, the fit's defaults but the window lengths: 2, 16 and 20 (past the default
truncation at 16, so a detached state is in the chain), two iterations each, with observation noise.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def digest(tensors) -> str:
    """SHA-256 of the tensors' bytes (contiguous, in order), the first 16 hex digits."""
    h = hashlib.sha256()
    for t in tensors:
        h.update(t.detach().contiguous().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


def run(data, robot, windows: int, fused: bool, horizons=(2, 16, 20), per_horizon: int = 2) -> dict[str, str]:
    import torch

    from wresdyn.fit.gradfit import GradFitConfig, _FitLearner, window_loss
    from wresdyn.learn.window_fit import start_window_fit
    from wresdyn.sim import rollout

    cfg = GradFitConfig(windows=windows, horizon_curriculum=horizons, iterations=per_horizon * len(horizons),
                        fused_network=fused)
    rng, train, dt = start_window_fit(cfg, data)
    learner = _FitLearner(robot, data, cfg, None, rng, train, dt, lambda *_: None)
    it = learner._iteration
    out = {}

    # one window batch by hand, as GradFitIteration._run does it, to see the rollout and the gradients before the clip
    h = max(horizons)
    traj, start = learner.bank.draw(rng, windows, h)
    noise = torch.randn((h, windows, learner.n_obs), generator=torch.Generator().manual_seed(7))
    window = learner.bank.window(traj, start, h)
    policy = learner.policy
    if it.fused is not None:
        it.fused.begin(h, windows)
    r = rollout(learner.sim, window, policy if it.fused is None else it.fused, grad=True,
                truncation=cfg.grad_truncation, obs_noise=learner.obs_noise, noise=noise)
    loss, _ = window_loss(cfg, r.q[:, 1:], r.qd[:, 1:], r.actions, window.q[:, 1:], window.qd[:, 1:],
                          it.torque_scale, it.weights)
    loss.backward()
    if it.fused is not None:
        it.fused.finish()
    out["rollout"] = digest([r.q, r.qd, r.actions])
    out["loss"] = digest([loss])
    out["grads"] = digest([p.grad for p in policy.parameters()])
    policy.zero_grad(set_to_none=True)

    parts = []
    for i, hh in enumerate(h for h in horizons for _ in range(per_horizon)):
        _, p = learner.step(i, hh, cfg.lr)
        parts.append(p)
    out["iterations"] = digest(parts)
    out["weights"] = digest(list(policy.state_dict().values()))
    return out


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--windows", type=int, default=8)
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    args = p.parse_args()
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    for fused in (False, True):
        d = run(data, robot, args.windows, fused)
        print(f"fused_network {fused}: " + "  ".join(f"{k} {v}" for k, v in d.items()))


if __name__ == "__main__":
    main()
