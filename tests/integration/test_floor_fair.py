"""The floor benchmark's summary over seeds (``benchmarks/skills/floor_fair.py``) on results written by hand."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(folder: Path, seed: int, success: list[int], falls: int, oracle_g: float) -> None:
    def policy(ok, g):
        motions = [{"motion": f"heldout_step_{i}", "success": float(s)} for i, s in enumerate(ok)]
        return {"mean": {"success": sum(ok) / len(ok), "falls": falls, "drifts": 1, "diverged": 0, "mpjpe": 0.02,
                         "g_mpjpe": g}, "motions": motions}

    heldout = {"a_nominal": policy([0, 1, 0, 0], 0.050), "b_calibrated": policy(success, 0.030),
               "d_oracle": policy([1, 1, 1, 1], oracle_g)}
    results = {"config": {"num_worlds": 4096, "oracle_num_worlds": 4096, "iterations": 1000, "finetune": 300,
                          "seed": seed},
               "policies": list(heldout), "real": {"heldout": heldout}}
    folder.mkdir(parents=True)
    (folder / "results.json").write_text(json.dumps(results))


def _summary(tmp_path: Path, oracle_g: float) -> tuple[dict, str]:
    for seed in (0, 1):
        _run(tmp_path / f"s{seed}", seed, [1, 1, 1, seed], 2 * seed, oracle_g)
    subprocess.run([sys.executable, str(ROOT / "benchmarks/skills/floor_fair.py"), str(tmp_path / "out"),
                    "--default", str(tmp_path / "s0"), str(tmp_path / "s1")], check=True, capture_output=True)
    return (json.loads((tmp_path / "out/summary.json").read_text()),
            (tmp_path / "out/table.md").read_text())


def test_summary_fields_means_and_interval(tmp_path):
    summary, table = _summary(tmp_path, oracle_g=0.020)
    b = summary["default"]["b"]
    assert list(b) == ["success", "falls", "mpjpe_mrad", "gmpjpe_mm", "worlds", "iterations", "seeds"]
    assert b["success"] == pytest.approx(0.875) and b["falls"] == pytest.approx(1.0)
    assert b["gmpjpe_mm"] == pytest.approx(30.0) and b["seeds"] == [0, 1]
    assert (b["worlds"], b["iterations"]) == (4096, 1300) and summary["default"]["a"]["iterations"] == 1000
    # Wilson's interval of 7/8 and the gap closed on g-MPJPE, (50 - 30) / (50 - 20)
    assert "88 % (7/8; 53–98 %)" in table and "| 67 % |" in table


def test_no_gap_ratio_when_the_oracle_does_not_beat_a(tmp_path):
    _, table = _summary(tmp_path, oracle_g=0.060)
    assert "no gap ratio" in table and "%" not in table.split("(b) b_calibrated")[1].split("|")[7]


def _probe(tmp_path: Path, env: dict, fits: bool = True) -> subprocess.CompletedProcess:
    """``floor_fair_probe.sh`` run from ``tmp_path`` (its dataset a stand-in file), its ``/root`` under it."""
    (tmp_path / "data/uneven_probe").mkdir(parents=True)
    (tmp_path / "data/uneven_probe/dataset.npz").touch()
    for c in ("calibrated", "delta_action") if fits else ():
        (tmp_path / "src/unvp_fits" / c).mkdir(parents=True)
        (tmp_path / "src/unvp_fits" / c / "policy.pt").touch()
    (tmp_path / "src").mkdir(exist_ok=True)
    return subprocess.run(["bash", str(ROOT / "benchmarks/skills/floor_fair_probe.sh"), "src", "log"], cwd=tmp_path,
                          env={"PATH": "/usr/bin:/bin", "ROOT": str(tmp_path / "root"), **env}, capture_output=True,
                          text=True)


def test_probe_runs_refuse_missing_corrections(tmp_path):
    done = _probe(tmp_path, {"DRY": "1", "GPUS": "0"}, fits=False)
    assert done.returncode == 2 and "unvp_fits/calibrated/policy.pt is missing" in done.stderr


def test_probe_runs_dry_take_the_gpus_in_turn_and_touch_nothing(tmp_path):
    done = _probe(tmp_path, {"DRY": "1", "GPUS": "0 1"})
    lines = done.stdout.splitlines()
    assert done.returncode == 0 and len(lines) == 3
    assert [ln.split()[0] for ln in lines] == ["CUDA_VISIBLE_DEVICES=0", "CUDA_VISIBLE_DEVICES=1",
                                               "CUDA_VISIBLE_DEVICES=0"]
    assert all(f"--seed {s} " in ln and f"root/floor_unvp_s{s} " in ln for s, ln in enumerate(lines))
    assert all(f"--calibrated {tmp_path}/root/unvp_fits/calibrated" in ln for ln in lines)
    assert not (tmp_path / "log").exists() and not (tmp_path / "root").exists()


FULL = ROOT / "benchmarks/results/floor_fair/full"
FINETUNED = ("b_calibrated", "c_delta_action", "d_oracle", "e_randomized", "f_calibrated_narrow")


def _committed_base(tmp_path: Path, base: str) -> None:
    """``src/<base>_s0..2`` holding the committed runs' ``config.json`` files, all the set-up's check reads."""
    for s in range(3):
        for p in FINETUNED:
            (tmp_path / f"src/{base}_s{s}/skills/{p}").mkdir(parents=True)
            (tmp_path / f"src/{base}_s{s}/skills/{p}/config.json").write_bytes(
                (FULL / f"{base}_s{s}/skills/{p}/config.json").read_bytes())


def _dry_at_root(tmp_path: Path, env: dict) -> subprocess.CompletedProcess:
    """A dry run with ROOT /root, where the committed skills' paths point (a dry run copies nothing there)."""
    return subprocess.run(["bash", str(ROOT / "benchmarks/skills/floor_fair_probe.sh"), "src", "log"], cwd=tmp_path,
                          env={"PATH": "/usr/bin:/bin", "ROOT": "/root", "DRY": "1", "GPUS": "0", "REUSE": "1",
                               **env}, capture_output=True, text=True)


def _commands(done: subprocess.CompletedProcess) -> list[str]:
    return [ln for ln in done.stdout.splitlines() if not ln.startswith("# ")]


def test_probe_runs_reuse_write_where_d_and_e_were_trained(tmp_path):
    done = _probe(tmp_path, {"DRY": "1", "GPUS": "0", "REUSE": "1"})
    assert done.returncode == 2 and "REUSE=1 needs src/floor_unv_s0" in done.stderr
    _committed_base(tmp_path, "floor_unv")
    done = _dry_at_root(tmp_path, {})
    lines = _commands(done)
    assert done.returncode == 0 and len(lines) == 3, done.stderr
    assert all(f"--out /root/floor_unv_s{s} --calibrated /root/unvp_fits/calibrated "
               "--delta /root/unvp_fits/delta_action" in ln for s, ln in enumerate(lines))
    assert "# floor_unvp_s1: /root/floor_unv_s1 from src/floor_unv_s1, keeping d_oracle e_randomized, retraining " \
           "b_calibrated c_delta_action f_calibrated_narrow" in done.stdout.splitlines()


def test_probe_runs_reuse_keep_c_of_the_probe_runs(tmp_path):
    """The effort line search's calibrated corrections: (b) and (f) retrained, (c), (d), (e) of the probe runs."""
    _probe(tmp_path, {"DRY": "1", "GPUS": "0"})
    (tmp_path / "src/unvp55_fits/calibrated").mkdir(parents=True)
    (tmp_path / "src/unvp55_fits/calibrated/policy.pt").touch()
    _committed_base(tmp_path, "floor_unvp")
    done = _dry_at_root(tmp_path, {"BASE": "floor_unvp", "NAME": "floor_unvp55", "CAL": "/root/unvp55_fits/calibrated",
                                   "KEEP": "c_delta_action d_oracle e_randomized"})
    lines = _commands(done)
    assert done.returncode == 0 and len(lines) == 3, done.stderr
    assert all(f"--seed {s} " in ln and f"--out /root/floor_unv_s{s} --calibrated /root/unvp55_fits/calibrated "
               "--delta /root/unvp_fits/delta_action" in ln for s, ln in enumerate(lines))
    assert "# /root/unvp55_fits/calibrated: from src/unvp55_fits/calibrated unless there" in done.stdout
    assert "# floor_unvp55_s2: /root/floor_unv_s2 from src/floor_unvp_s2, keeping c_delta_action d_oracle " \
           "e_randomized, retraining b_calibrated f_calibrated_narrow" in done.stdout.splitlines()


def test_probe_runs_reuse_refuse_a_kept_policy_on_other_corrections(tmp_path):
    _probe(tmp_path, {"DRY": "1", "GPUS": "0"})
    _committed_base(tmp_path, "floor_unv")  # (c) trained on unv_fits/, the command passes unvp_fits/
    done = _dry_at_root(tmp_path, {"KEEP": "c_delta_action d_oracle e_randomized"})
    assert done.returncode == 2 and not done.stdout
    assert done.stderr == "error: src/floor_unv_s0/skills/c_delta_action/config.json records corrections " \
                          "'/root/unv_fits/delta_action', the command passes '/root/unvp_fits/delta_action'\n"
    (tmp_path / "src/floor_unv_s1/skills/d_oracle/config.json").unlink()
    done = _dry_at_root(tmp_path, {"RUNS": "floor_unvp_s1"})
    assert done.returncode == 2 and "KEEP names d_oracle but src/floor_unv_s1/skills/d_oracle/config.json" in \
        done.stderr
    done = _dry_at_root(tmp_path, {"KEEP": "a_nominal"})
    assert done.returncode == 2 and "KEEP names a_nominal, not one of b_calibrated" in done.stderr
    done = _dry_at_root(tmp_path, {"BASE": "floor_unvp"})
    assert done.returncode == 2 and "NAME and BASE are both floor_unvp" in done.stderr


def test_probe_runs_narrowed_keep_each_run_its_own_seed(tmp_path):
    _probe(tmp_path, {"DRY": "1", "GPUS": "0"})
    _committed_base(tmp_path, "floor_unv")
    done = _dry_at_root(tmp_path, {"GPUS": "1", "RUNS": "floor_unvp_s2 floor_unvp_s0"})
    lines = _commands(done)
    assert len(lines) == 2 and all(ln.startswith("CUDA_VISIBLE_DEVICES=1 ") for ln in lines)
    assert "--seed 2 " in lines[0] and "--out /root/floor_unv_s2 " in lines[0]
    assert "--seed 0 " in lines[1] and "--out /root/floor_unv_s0 " in lines[1]


def _fake_base(tmp_path: Path, base: str, delta: str = "") -> None:
    """``src/<base>_s0..2`` with every fine-tuned policy (its ``config.json`` naming its corrections under the test's
    ROOT), results and a held-out ledger of two lines."""
    fits = {"b_calibrated": "unvp_fits/calibrated", "c_delta_action": delta or "unvp_fits/delta_action",
            "f_calibrated_narrow": "unvp_fits/calibrated"}
    for s in range(3):
        run = tmp_path / f"src/{base}_s{s}"
        for p in FINETUNED:
            (run / "skills" / p).mkdir(parents=True)
            correction = str(tmp_path / "root" / fits[p]) if p in fits else ""
            (run / "skills" / p / "config.json").write_text(json.dumps({"init": "a", "correction": correction},
                                                                       indent=2))
        (run / "results.json").write_text("{}")
        (run / "heldout_ledger.jsonl").write_text('{"seed": 0}\n{"seed": 0}\n')


def test_probe_runs_reuse_set_up_once_keeping_d_and_e(tmp_path):
    _fake_base(tmp_path, "floor_unv")
    # the deploy itself fails at once here (no wresdyn on this PATH's python's path): only the set-up is checked
    done = _probe(tmp_path, {"GPUS": "0", "REUSE": "1", "STAGGER": "0"})
    assert "STAGES" in {p.name for p in (tmp_path / "log").iterdir()}, done.stderr
    for s in range(3):
        run = tmp_path / f"root/floor_unv_s{s}"
        assert sorted(p.name for p in (run / "skills").iterdir()) == ["d_oracle", "e_randomized"]
        assert (run / ".probe_reuse").exists() and (run / "heldout_ledger.jsonl").exists()
        assert not (run / "results.json").exists()
    (tmp_path / "root/floor_unv_s0/skills/b_calibrated").mkdir()  # progress of a run, kept by a rerun
    subprocess.run(["bash", str(ROOT / "benchmarks/skills/floor_fair_probe.sh"), "src", "log"], cwd=tmp_path,
                   env={"PATH": "/usr/bin:/bin", "ROOT": str(tmp_path / "root"), "GPUS": "0", "REUSE": "1",
                        "STAGGER": "0"}, capture_output=True, text=True)
    assert (tmp_path / "root/floor_unv_s0/skills/b_calibrated").exists()


def test_probe_runs_reuse_set_up_keeping_c_with_other_calibrated_corrections(tmp_path):
    _fake_base(tmp_path, "floor_unvp")
    (tmp_path / "src/unvp55_fits/calibrated").mkdir(parents=True)
    (tmp_path / "src/unvp55_fits/calibrated/policy.pt").write_text("55")
    done = _probe(tmp_path, {"GPUS": "0", "REUSE": "1", "STAGGER": "0", "BASE": "floor_unvp", "NAME": "floor_unvp55",
                             "KEEP": "c_delta_action d_oracle e_randomized",
                             "CAL": str(tmp_path / "root/unvp55_fits/calibrated")})
    assert (tmp_path / "log/STAGES").exists(), done.stderr
    assert (tmp_path / "root/unvp55_fits/calibrated/policy.pt").read_text() == "55"
    assert (tmp_path / "root/unvp_fits/delta_action/policy.pt").exists()
    assert not (tmp_path / "root/unvp_fits/calibrated").exists()
    for s in range(3):
        run = tmp_path / f"root/floor_unv_s{s}"
        assert sorted(p.name for p in (run / "skills").iterdir()) == ["c_delta_action", "d_oracle", "e_randomized"]
        assert len((run / "heldout_ledger.jsonl").read_text().splitlines()) == 2  # the base's scorings
        assert (run / ".probe_reuse").read_text().startswith(f"floor_unvp55_s{s}: kept c_delta_action")
        assert not (run / "results.json").exists()
    assert "floor_unvp55_s0.out" in {p.name for p in (tmp_path / "log").iterdir()}


def test_compare_the_probe_runs_with_the_committed_ones_on_validation():
    """``floor_fair_compare.py`` on the committed uneven runs: the figures the probe configuration was chosen on."""
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks/skills/floor_fair_compare.py"),
                           *(str(FULL / f"floor_unv_s{s}") for s in range(3)), "--",
                           *(str(FULL / f"floor_unvp_s{s}") for s in range(3)), "--names", "floor_unv", "floor_unvp"],
                          check=True, capture_output=True, text=True)
    lines = done.stdout.splitlines()
    assert lines[0] == "Validation success on the real robot, mean over seeds, floor_unv -> floor_unvp:"
    assert lines[2] == "| policy | all | squat | weight_shift | kick | wave |"
    # (b) 64.6 -> 75.0 % and (f) 75.0 -> 83.3 % (full/MANIFEST.md); the squats gained, the kicks lost
    assert "| b_calibrated | 64.6 -> 75.0 | 33.3 -> 100.0 | 100.0 -> 100.0 | 25.0 -> 0.0 | 100.0 -> 100.0 |" in lines
    assert "| f_calibrated_narrow | 75.0 -> 83.3 | 25.0 -> 100.0 | 100.0 -> 100.0 | 75.0 -> 33.3 | 100.0 -> 100.0 |" \
        in lines
    assert "| d_oracle | 100.0 -> 100.0 | 100.0 -> 100.0 | 100.0 -> 100.0 | 100.0 -> 100.0 | 100.0 -> 100.0 |" in lines


def test_compare_the_line_search_runs_with_the_probe_runs_on_validation():
    """The packed ``floor_unvp55_s0``, ``_s1`` against the probe runs of the same seeds: what validation chose on."""
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks/skills/floor_fair_compare.py"),
                           *(str(FULL / f"floor_unvp_s{s}") for s in range(2)), "--",
                           *(str(FULL / f"floor_unvp55_s{s}") for s in range(2)), "--names", "floor_unvp",
                           "floor_unvp55"], check=True, capture_output=True, text=True)
    # one kick more of 8 for (b) and for (f) (benchmarks/results/floor_fair/unvp55_choice/MANIFEST.md)
    assert "| b_calibrated | 75.0 -> 78.1 | 100.0 -> 100.0 | 100.0 -> 100.0 | 0.0 -> 12.5 | 100.0 -> 100.0 |" \
        in done.stdout.splitlines()
    assert "| f_calibrated_narrow | 87.5 -> 90.6 | 100.0 -> 100.0 | 100.0 -> 100.0 | 50.0 -> 62.5 | 100.0 -> 100.0 |" \
        in done.stdout.splitlines()
    assert (ROOT / "benchmarks/results/floor_fair/unvp55_choice/validation_two_seeds.md").read_text() == done.stdout


@pytest.mark.parametrize("seed", [0, 1])
def test_line_search_runs_ledger_every_held_out_scoring(seed):
    """Each packed run's held-out ledger is its base's, the same motions, and one line more: its own scoring."""
    base = (FULL / f"floor_unvp_s{seed}/heldout_ledger.jsonl").read_text().splitlines()
    run = FULL / f"floor_unvp55_s{seed}"
    lines = (run / "heldout_ledger.jsonl").read_text().splitlines()
    assert lines[:-1] == base and len(lines) == 3 and json.loads(lines[-1])["seed"] == seed
    assert (run / ".probe_reuse").read_text().startswith(f"floor_unvp55_s{seed}: kept c_delta_action d_oracle "
                                                          "e_randomized of floor_unvp")


def test_compare_needs_two_configurations():
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks/skills/floor_fair_compare.py"),
                           str(FULL / "floor_unv_s0")], capture_output=True, text=True)
    assert done.returncode == 1 and "RUN_A... -- RUN_B..." in done.stderr
