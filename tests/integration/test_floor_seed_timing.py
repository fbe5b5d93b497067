"""``benchmarks/skills/floor_seed_timing.sh``: one floor seed's command, its input checks, and the time of each call
appended (the deploy refusing a bad seed at once in the call test)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks/skills/floor_seed_timing.sh"
SIX = "a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"


def _run(out, env: dict, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), str(out)], cwd=cwd, env={"PATH": "/usr/bin:/bin", **env},
                          capture_output=True, text=True, timeout=120)


def test_dry_prints_the_whole_seed_on_gpu_0_fitting_the_corrections_and_touches_nothing(tmp_path):
    done = _run(tmp_path / "out", {"DRY": "1"})
    assert done.returncode == 0, done.stderr
    assert done.stdout == (
        "CUDA_VISIBLE_DEVICES=0 WRESDYN_LOG_CLOCK=1 python3 -m wresdyn.cli deploy data/dataset.npz --floor --full "
        "--device cuda:0 --mismatch data/mismatch_default.toml --seed 3 --nominal floor_nominal "
        f"--policies {SIX} --no-animation --out {tmp_path}/out/floor_seed_s3\n")
    assert not (tmp_path / "out").exists()
    done = _run(tmp_path / "out", {"DRY": "1", "SEED": "4", "GPU": "2"})
    assert done.stdout.startswith("CUDA_VISIBLE_DEVICES=2 ") and "--device cuda:0 " in done.stdout
    assert " --seed 4 " in done.stdout


def test_beside_shares_the_gpu_with_that_many_fine_tunings_and_refuses_more_than_there_are(tmp_path):
    done = _run(tmp_path / "out", {"DRY": "1", "BESIDE": "3"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.endswith(" --beside-devices cuda:0 cuda:0 cuda:0\n")
    done = _run(tmp_path / "out", {"DRY": "1", "BESIDE": "1", "TINY": "1"})
    assert done.stdout.endswith(" --beside-devices cpu\n")
    for bad in ("4", "x"):
        done = _run(tmp_path / "out", {"DRY": "1", "BESIDE": bad})
        assert done.returncode == 2 and done.stdout == ""
        assert done.stderr == f"error: BESIDE={bad}: 0 to 3 (the simulated fine-tunings after (b))\n"


def test_tiny_is_the_same_command_small_on_the_cpu(tmp_path):
    done = _run(tmp_path / "out", {"DRY": "1", "TINY": "1"})
    cmd = done.stdout
    assert done.returncode == 0 and "--device cpu " in cmd and "--num-worlds 4 " in cmd and "--finetune 1 " in cmd
    assert "--policies a_nominal b_calibrated c_delta_action d_oracle --no-animation " in cmd
    assert "--calibrated benchmarks/results/floor_fair/full/floor_def_s0/calibrated " in cmd
    # set empty: the corrections fitted inside, as on the GPU
    done = _run(tmp_path / "out", {"DRY": "1", "TINY": "1", "CAL": "", "DELT": ""})
    assert done.returncode == 0 and "--calibrated" not in done.stdout and "--delta" not in done.stdout


def test_missing_inputs_are_refused(tmp_path):
    done = _run(tmp_path / "out", {"DRY": "1"}, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr == "error: data/dataset.npz is missing (tracked: check out the " \
                                                   "repository)\n"
    done = _run(tmp_path / "out", {"DRY": "1", "CAL": str(tmp_path / "none")})
    assert done.returncode == 2 and f"{tmp_path}/none/policy.pt is missing" in done.stderr


def test_each_call_appends_its_seconds_and_rc(tmp_path):
    """Two real calls of the deploy that refuse their seed at once (nothing trained): each call's seconds and exit
    status appended to time.txt, the deploy's own error in deploy.log, the machine recorded before each call."""
    env = {"PYTHON": sys.executable, "SEED": "-1"}
    for _ in range(2):
        done = _run(tmp_path / "out", env)
        assert done.returncode == 2, done.stderr
    times = [ln.split() for ln in (tmp_path / "out/time.txt").read_text().splitlines()]
    assert [t[2:] for t in times] == [["s", "rc=2"], ["s", "rc=2"]]
    # whole seconds by the shell's clock: a refused call may straddle one tick
    assert all(int(t[1]) <= 5 for t in times)
    assert done.stdout == f"calls so far: 2, {int(times[0][1]) + int(times[1][1])} s in all; last rc=2\n"
    assert (tmp_path / "out/machine.txt").read_text().count("== call at ") == 2
    log = (tmp_path / "out/deploy.log").read_text().splitlines()
    assert log == ["wresdyn deploy: error: floor.seed = -1 must be >= 0"] * 2
    assert not (tmp_path / "out/floor_seed_s-1").exists()
