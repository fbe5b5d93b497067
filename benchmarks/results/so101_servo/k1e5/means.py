"""Per run the mean |dq| [rad] of each split its eval_metrics.json holds, then the mean validation of each setting
over its seeds: the choices of this folder, of ../hybrid/, ../load_friction/ and ../profile_k1e5/ (run from
benchmarks/results/so101_servo/).

    python k1e5/means.py
"""

import json
from pathlib import Path

SETTINGS = {
    "kappa 3e4, effort reset": ["effort/k3e4_reset", "effort/k3e4_reset_seed1", "k1e5/k3e4_reset_seed2"],
    "kappa 3e4, effort reset, backlash and encoder offsets (benchmarks/real/so101_servo_real.sh's recipe)": [
        "backlash/bl_seed0", "k1e5/k3e4_bl_seed1", "k1e5/k3e4_bl_seed2"],
    "kappa 1e5, effort reset, seeds 0-1 (the kappa choice)": ["effort/k1e5_reset", "k1e5/reset_seed1"],
    "kappa 1e5, effort reset": ["effort/k1e5_reset", "k1e5/reset_seed1", "k1e5/reset_seed2"],
    "kappa 1e5, effort reset, backlash and encoder offsets": ["k1e5/bl_seed0", "k1e5/bl_seed1", "k1e5/bl_seed2"],
    "servo model alone (effort/k1e5_reset)": ["effort/k1e5_reset"],
    "hybrid, torque residual (MLP, the default)": ["hybrid/torque", "hybrid/torque_seed1"],
    "hybrid, delta action (MLP)": ["hybrid/delta", "hybrid/delta_seed1"],
    "hybrid, torque residual (GRU)": ["hybrid/gru", "hybrid/gru_seed1"],
    "hybrid, delta action (GRU)": ["hybrid/gru_delta", "hybrid/gru_delta_seed1"],
    "kappa 1e5, effort reset, load friction (load_friction/)": [
        "load_friction/lf_seed0", "load_friction/lf_seed1", "load_friction/lf_seed2"],
    "the reported recipe on three seeds: hybrid, delta action (GRU) on effort/k1e5_reset": [
        "hybrid/gru_delta", "hybrid/gru_delta_seed1", "hybrid/gru_delta_seed2"],
    "kappa 1e5, effort reset, the goal profile at LeRobot's 38.96 rad/s^2 (profile_k1e5/)": [
        "profile_k1e5/ga_seed0", "profile_k1e5/ga_seed1", "profile_k1e5/ga_seed2"],
    "load friction + hybrid, delta action (GRU) on load_friction/lf_seed0": [
        "load_friction/lf_gru_delta", "load_friction/lf_gru_delta_seed1", "load_friction/lf_gru_delta_seed2"],
}


def splits(run: str) -> dict:
    return {s: v["pd_residual"]["mean_abs_dq"] for s, v in
            json.loads(Path(run, "eval_metrics.json").read_text())["splits"].items()}


def main() -> None:
    for name, runs in SETTINGS.items():
        runs = [r for r in runs if Path(r, "eval_metrics.json").exists()]
        for r in runs:
            print(f"{r}: " + "  ".join(f"{s} {v:.5f}" for s, v in splits(r).items()))
        vals = [splits(r)["validation"] for r in runs]
        each = " / ".join(f"{v:.5f}" for v in vals)
        two = f"; seeds 0-1: {sum(vals[:2]) / 2:.6f}" if len(vals) > 2 else ""
        print(f"  {name}: mean validation {sum(vals) / len(vals):.5f} rad over {len(vals)} seed(s) ({each}){two}\n")


if __name__ == "__main__":
    main()
