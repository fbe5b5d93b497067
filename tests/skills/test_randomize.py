"""Domain randomisation of the simulated plants (:mod:`wresdyn.skills.randomize`): the draws read back from the Newton
model arrays, the delay line per world, the narrow ranges from an identifiability report, and the benchmark's (e), (f)
policies through the real code path (Newton, rsl-rl, MuJoCo C for the real robot) at tiny sizes."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.randomize import NARROW_DEFAULT, NARROW_FLOOR, Randomization, narrow_ranges

import skill_runs
from skill_runs import fit_run

RATE = skill_runs.RATE
WORLDS = 4


def model_fields(plant) -> dict:
    """The per-world physical fields as the Newton model holds them (numpy)."""
    import warp as wp

    m, sim, w = plant.sim.model, plant.sim, plant.num_worlds
    joint = lambda a: wp.to_torch(a).view(w, -1)[:, sim.qd_index].numpy().copy()  # noqa: E731
    body = lambda a, *s: wp.to_torch(a).view(w, -1, *s).numpy().copy()  # noqa: E731
    return {"kp": joint(m.joint_target_ke), "kd": joint(m.joint_target_kd), "armature": joint(m.joint_armature),
            "friction": joint(m.joint_friction), "effort": joint(m.joint_effort_limit),
            "body_mass": body(m.body_mass), "body_inv_mass": body(m.body_inv_mass),
            "body_com": body(m.body_com, 3), "body_inertia": body(m.body_inertia, 3, 3),
            "delay": (plant._m + plant._alpha).numpy() / RATE}


@pytest.fixture(scope="module")
def drawn(humanoid):
    """Two plants of the same seed and one of another, with their model fields as drawn."""
    torch.set_num_threads(1)
    cfg = Randomization(seed=3)
    plants = [SimPlant(humanoid, WORLDS, RATE, 5, randomization=c)
              for c in (cfg, cfg, dataclasses.replace(cfg, seed=4))]
    return cfg, plants, [model_fields(p) for p in plants]


def test_a_draw_writes_every_world_within_its_ranges(humanoid, drawn):
    cfg, plants, (f, _, _) = drawn
    nominal = PhysicalParams.nominal(humanoid)
    eps = 1e-5  # float32 model arrays
    for field, rng in (("kp", cfg.kp_scale), ("kd", cfg.kd_scale), ("armature", cfg.armature_scale),
                       ("effort", cfg.effort_scale)):
        ratio = f[field] / getattr(nominal, field)
        assert (ratio > rng[0] - eps).all() and (ratio < rng[1] + eps).all(), field
        assert np.ptp(ratio, axis=0).min() > 1e-3, field  # the worlds differ, joint by joint
    frac = f["friction"] / nominal.effort
    assert (frac >= 0).all() and (frac < cfg.friction[1] + eps).all() and np.ptp(frac, axis=0).min() > 1e-4
    moving = nominal.body_mass > 0
    s = f["body_mass"][:, moving] / nominal.body_mass[moving]
    assert (s > cfg.mass_scale[0] - eps).all() and (s < cfg.mass_scale[1] + eps).all()
    # the inertia scales with the mass (uniform density) and the inverse mass follows
    i_ratio = f["body_inertia"][:, moving, 0, 0] / nominal.body_inertia[moving, 0, 0]
    assert np.abs(i_ratio - s).max() < 1e-4
    assert np.abs(f["body_inv_mass"][:, moving] * f["body_mass"][:, moving] - 1).max() < 1e-5
    torso = list(humanoid.body_names).index(cfg.com_body)
    off = np.abs(f["body_com"][:, torso] - nominal.body_com[torso])
    assert (off <= np.asarray(cfg.com_offset) + eps).all() and off.max() > 1e-3
    others = [b for b in range(len(humanoid.body_names)) if b != torso]
    assert np.abs(f["body_com"][:, others] - nominal.body_com[others]).max() < 1e-6
    # one delay per world, every joint alike, in range, quantised by nothing finer than the float32 fraction
    d = f["delay"]
    assert np.ptp(d, axis=1).max() < 1e-6 and (d >= cfg.delay[0] - 1e-6).all() and (d <= cfg.delay[1] + 1e-6).all()
    assert np.ptp(d[:, 0]) > 1e-3
    assert np.allclose(d, plants[0].randomizer.delay, atol=1e-6)


def test_the_same_seed_draws_the_same_worlds(drawn):
    _, _, (a, b, c) = drawn
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    assert not np.allclose(a["kp"], c["kp"])


def test_a_reset_redraws_only_the_worlds_it_resets(humanoid):
    torch.set_num_threads(1)
    plant = SimPlant(humanoid, WORLDS, RATE, 5, randomization=Randomization(seed=1))
    before = model_fields(plant)
    q = torch.zeros(2, humanoid.n_dof)
    plant.reset(torch.tensor([1, 2]), q, q)
    after = model_fields(plant)
    for k in ("kp", "body_mass", "delay"):
        assert np.array_equal(before[k][[0, 3]], after[k][[0, 3]]), k
        assert not np.allclose(before[k][[1, 2]], after[k][[1, 2]]), k
    startup = SimPlant(humanoid, WORLDS, RATE, 5, randomization=Randomization(seed=1, redraw="startup"))
    first = model_fields(startup)["kp"]
    startup.reset(torch.tensor([1, 2]), q, q)
    assert np.array_equal(first, model_fields(startup)["kp"])


def test_a_randomised_delay_line_delays_each_world_by_its_own_draw(humanoid):
    """A step of the command reaches each world's drive after that world's delay: worlds of one draw, each
    compared with a plant without randomisation whose identified delay is that world's."""
    torch.set_num_threads(1)
    cfg = Randomization(seed=2, kp_scale=(1, 1), kd_scale=(1, 1), armature_scale=(1, 1), effort_scale=(1, 1),
                        mass_scale=(1, 1), com_offset=(0, 0, 0), friction=(0, 0))
    plant = SimPlant(humanoid, WORLDS, RATE, 1, randomization=cfg)
    q0, cmd = torch.zeros(WORLDS, humanoid.n_dof), torch.full((WORLDS, humanoid.n_dof), 0.05)
    plant.reset(torch.arange(WORLDS), q0, q0.clone())
    delay = plant.randomizer.delay.copy()
    qs = [plant.step(cmd)[0] for _ in range(20)]
    for w in range(WORLDS):
        p = PhysicalParams.nominal(humanoid)
        p.delay = delay[w]
        ref = SimPlant(humanoid, 1, RATE, 1, physics=p)
        ref.reset(torch.arange(1), q0[:1], q0[:1].clone())
        for k in range(20):
            assert torch.allclose(ref.step(cmd[:1])[0][0], qs[k][w], atol=1e-6), (w, k)


def test_on_the_floor_a_draw_reaches_the_mujoco_model(floating):
    """On the floor the robot's collision shapes carry each world's drawn friction and the shared floor the range's
    low end (MuJoCo takes the larger of two geoms'); the drawn masses reach the MuJoCo model the solver steps. The
    threaded CPU worlds, which share world 0's physics, are refused."""
    from wresdyn.errors import WresdynError

    torch.set_num_threads(1)
    cfg = Randomization(seed=1)
    plant = SimPlant(floating, 1, RATE, 5, ground=True, randomization=cfg)
    mj, mu = plant.sim.solver.mj_model, plant.randomizer.floor_friction[0]
    assert cfg.floor_friction[0] < mu < cfg.floor_friction[1]
    floor = mj.geom_bodyid == 0
    assert np.allclose(mj.geom_friction[floor, 0], cfg.floor_friction[0])
    assert np.allclose(mj.geom_friction[~floor, 0], mu, atol=1e-6)
    drawn = plant.randomizer.values["body_mass"][0].numpy()
    assert np.allclose(mj.body_mass[1:], drawn, rtol=1e-6) and not np.allclose(
        drawn, PhysicalParams.nominal(floating).body_mass)
    with pytest.raises(WresdynError, match="per-world physics"):
        SimPlant(floating, 2, RATE, 5, ground=True, randomization=cfg)


def test_narrow_ranges_follow_the_identified_errors(tmp_path, humanoid):
    """(f)'s half-widths: 2 SE of a parameter the report covers (at least the floor, at most (e)'s), ±10 % of one it
    does not, and ±10 % of everything without a report."""
    from wresdyn.identify.identifiability import Identifiability, write_identifiability

    j = humanoid.joint_names
    names = [f"kp:{j[0]}", f"kp:{j[1]}", f"kp:{j[2]}", f"armature:{j[0]}"]
    se = np.array([0.03, 0.001, 5.0, 0.04])
    p = len(names)
    found = Identifiability(names, np.ones(p), np.ones(p, bool), np.ones(p), np.ones(p), se, se, np.eye(p), 0.1,
                            100, [], [], 1, 10, 0.0)
    (tmp_path / "identify").mkdir()
    write_identifiability(tmp_path / "identify", found)
    cfg = Randomization()
    centre = PhysicalParams.nominal(humanoid)
    ranges, source = narrow_ranges(cfg, humanoid, centre, tmp_path)
    lo, hi = ranges.scale["kp"]
    assert hi[0] == pytest.approx(math.exp(0.06)) and lo[0] == pytest.approx(math.exp(-0.06))
    assert hi[1] == pytest.approx(1 + NARROW_FLOOR)  # the floor
    assert (lo[2], hi[2]) == pytest.approx(cfg.kp_scale)  # (e)'s at most
    assert hi[3] == pytest.approx(1 + NARROW_DEFAULT)  # not in the report
    assert ranges.scale["armature"][1][0] == pytest.approx(math.exp(0.08))
    assert "identifiability.json" in source and "2 SE" in source
    bare, source = narrow_ranges(cfg, humanoid, centre, tmp_path / "nothing")
    assert np.allclose(bare.scale["kd"][1], 1 + NARROW_DEFAULT) and "no identifiability report" in source


def test_a_skill_trains_on_a_randomised_plant(tmp_path, humanoid):
    """(e)'s plant under rsl-rl's PPO: two iterations on 4 worlds, the episodes' resets drawing new worlds."""
    from wresdyn.skills.env import SkillConfig, TrackingEnv
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import sim_plant
    from wresdyn.skills.skill_ppo import SkillPPOConfig, train_skill

    torch.set_num_threads(1)
    motions = make_motions(humanoid, {"train": 1, "validation": 1, "heldout": 1}, duration=0.4, rate_hz=RATE, seed=3)
    plant = sim_plant("nominal", humanoid, WORLDS, RATE, 5, randomization=Randomization(seed=5))
    first = model_fields(plant)["kp"]
    env = TrackingEnv(plant, motions.split("train"), SkillConfig(decimation=5))
    ppo = SkillPPOConfig(iterations=2, num_steps_per_env=8, hidden_dims=(16,), num_mini_batches=1, torch_threads=1)
    assert train_skill(env, ppo, tmp_path / "e", log=lambda *_: None)["iterations"] == 2
    # the worlds whose 0.4 s motion ended were drawn anew, joint by joint
    assert (np.abs(model_fields(plant)["kp"] - first) > 1e-4).all(axis=1).any()


def test_the_floor_benchmark_refuses_randomised_policies_on_the_cpu_before_it_starts(tmp_path, humanoid):
    from wresdyn.errors import WresdynError
    from wresdyn.experiments.deploy_config import FloorDeployConfig
    from wresdyn.experiments.skills import run_benchmark

    out = tmp_path / "floor"
    with pytest.raises(WresdynError, match="per-world physics"):
        run_benchmark(humanoid, None, out, FloorDeployConfig(), policies=("a_nominal", "e_randomized"))
    assert not out.exists()


@pytest.mark.slow  # ~45 s: the whole benchmark (fit runs given) with (a), (e), (f) deployed on the real robot
def test_randomised_baselines_train_and_deploy_through_the_benchmark(tmp_path, humanoid, data):
    """(e) and (f) fine-tuned from (a) on randomised plants and deployed on the real robot, at the smallest size."""
    from wresdyn.experiments.deploy_config import DeployConfig
    from wresdyn.experiments.skills import run_benchmark
    from wresdyn.skills.skill_config import SkillPPOConfig

    torch.set_num_threads(1)
    cal = fit_run(tmp_path, humanoid, data, "torque", physics=True)
    cfg = DeployConfig(train_per_family=1, validation_per_family=1, heldout_per_family=1, duration=0.4,
                       num_worlds=4, iterations=2, finetune=1)
    ppo = SkillPPOConfig(num_steps_per_env=4, hidden_dims=(16,), num_mini_batches=1, torch_threads=1)
    out = tmp_path / "deploy"
    res = run_benchmark(humanoid, data, out, cfg, calibrated=cal, ppo=ppo, animation=False,
                        policies=("a_nominal", "e_randomized", "f_calibrated_narrow"), log=lambda s: None)
    assert set(res["real"]["heldout"]) == {"reference", "a_nominal", "e_randomized", "f_calibrated_narrow"}
    assert res["randomization"]["seed"] == 0 and "no identifiability report" in res["randomization"]["narrow"]
    for name, setting in (("e_randomized", "randomized"), ("f_calibrated_narrow", "calibrated_narrow")):
        record = json.loads((out / "skills" / name / "config.json").read_text())
        assert record["num_worlds"] == 4 and record["setting"] == setting, record
        assert record["randomization"]["kp_scale"] == [0.8, 1.2]
        assert math.isfinite(res["real"]["heldout"][name]["mean"]["mpjpe"])
    assert "(e) (a) fine-tuned" in (out / "report.md").read_text()


def warp_pointers(*objects) -> dict:
    """Device address of every Warp array of ``objects`` (a Newton model, a MuJoCo Warp model or data): what a
    captured CUDA graph holds."""
    import warp as wp

    return {(i, k): v.ptr for i, o in enumerate(objects) for k, v in vars(o).items() if isinstance(v, wp.array)}


def test_the_draws_of_a_seed_are_those_the_smoke_figures_were_run_with(humanoid):
    """Seed 3, four worlds, worlds 1 and 2 redrawn on reset: the values the draws gave before redraws wrote in place
    (float32 model values, read back to 1e-6)."""
    torch.set_num_threads(1)
    plant = SimPlant(humanoid, WORLDS, RATE, 5, randomization=Randomization(seed=3))
    q = torch.zeros(2, humanoid.n_dof)
    plant.reset(torch.tensor([1, 2]), q, q)
    v = {k: t.numpy() for k, t in plant.randomizer.values.items()}
    kp = [[82.827026367, 88.062347412], [99.204872131, 88.634475708], [80.967636108, 103.861045837],
          [100.676895142, 116.220855713]]
    mass = [[1.039174318, 0.982882202], [0.913201869, 1.296197534], [0.818135619, 1.026046872],
            [0.931586683, 1.326187372]]
    assert np.allclose(v["kp"][:, :2], kp, rtol=1e-6, atol=0)
    assert np.allclose(v["body_mass"][:, 1:3], mass, rtol=1e-6, atol=0)
    assert np.allclose(v["friction"][:, 0], [1.337236047, 4.243315697, 1.827716708, 1.294463634], rtol=1e-6)
    assert np.allclose(v["body_com"].reshape(WORLDS, -1).sum(1), [-0.885374263, -0.872034815, -0.837009476,
                                                                  -0.802855948], rtol=1e-6)
    assert np.allclose(plant.randomizer.delay[:, 0], [0.002918555, 0.019272541, 0.007987468, 0.003604118], rtol=1e-6)


def _fresh_params(humanoid, values: dict, w: int) -> PhysicalParams:
    """World ``w``'s drawn physics as :class:`PhysicalParams` (float64 of the float32 draws)."""
    p = PhysicalParams.nominal(humanoid)
    for f, v in values.items():
        setattr(p, f, v[w].numpy().astype(np.float64))
    return p


def test_a_redraw_writes_in_place_and_each_world_steps_as_a_simulator_built_with_its_draw(humanoid):
    """After a reset redraws worlds 1 and 2 (every randomised quantity at once), no model array moved (a captured
    graph stays valid, and is kept), and each world steps as a one-world simulator given that world's draw through
    the whole-model path (set_physics)."""
    from wresdyn.sim import Simulator

    torch.set_num_threads(1)
    plant = SimPlant(humanoid, WORLDS, RATE, 1, randomization=Randomization(seed=4))
    sim = plant.sim
    before, sentinel = warp_pointers(sim.model), object()
    sim._graphs[7] = sentinel
    q0 = torch.zeros(2, humanoid.n_dof)
    plant.reset(torch.tensor([1, 2]), q0, q0)
    assert warp_pointers(sim.model) == before and sim._graphs[7] is sentinel
    del sim._graphs[7]
    values = {f: v.clone() for f, v in plant.randomizer.values.items()}
    target = torch.full((WORLDS, humanoid.n_dof), 0.2)
    sim.set_state(None, torch.zeros(WORLDS, humanoid.n_dof), torch.zeros(WORLDS, humanoid.n_dof))
    qs = [sim.step(target)[0] for _ in range(30)]
    for w in range(WORLDS):
        alone = Simulator(humanoid, 1, 1.0 / RATE)
        alone.set_physics(_fresh_params(humanoid, values, w))
        alone.set_state(None, torch.zeros(1, humanoid.n_dof), torch.zeros(1, humanoid.n_dof))
        for k in range(30):
            q = alone.step(target[:1])[0]
        assert torch.allclose(q[0], qs[-1][w], atol=1e-6), w  # float32, the same kernel
    assert (qs[-1][1] - qs[-1][0]).abs().max() > 1e-3  # the draws differ enough to be seen


MJW_DERIVED = ("body_mass", "body_inertia", "body_ipos", "body_subtreemass", "body_invweight0", "dof_armature",
               "dof_invweight0", "dof_frictionloss", "actuator_gainprm", "actuator_biasprm", "actuator_forcerange")
"""What Newton's SolverMuJoCo derives per world from the randomised model arrays (mujoco_warp's model)."""


def _equals_a_solver_built_on_the_drawn_model(plant, robot, redraws, ground: bool = False, tol: float = 1e-5) -> None:
    """Redraw ``redraws`` (lists of worlds, one reset each) on a mujoco_warp plant: nothing the solver holds moves
    (Newton model, mujoco_warp model and data: a captured graph stays valid), what it derives per world equals what
    a solver built on the drawn model derives, and the worlds step alike."""
    import warp as wp

    from wresdyn.sim import Simulator
    from wresdyn.sim.solvers import make_solver

    sim, w = plant.sim, plant.num_worlds
    holds = lambda s: warp_pointers(s.model, s.solver.mjw_model, s.solver.mjw_data)  # noqa: E731
    before = holds(sim)
    for ids in redraws:
        z = torch.zeros(len(ids), robot.n_dof, device=plant.device)
        if ground:
            pose = plant.base_pose[ids]
            plant.reset_full(torch.tensor(ids), pose, torch.zeros(len(ids), 6, device=plant.device), z, z)
        else:
            plant.reset(torch.tensor(ids), z, z)
    assert holds(sim) == before
    fresh = Simulator(robot, w, 1.0 / RATE, solver="mujoco", ground=ground, device=str(plant.device))
    names = ["joint_target_ke", "joint_target_kd", "joint_armature", "joint_friction", "joint_effort_limit",
             "body_mass", "body_com", "body_inertia", "body_inv_mass", "body_inv_inertia"]
    for name in names + (["shape_material_mu"] if ground else []):
        wp.copy(getattr(fresh.model, name), getattr(sim.model, name))
    fresh.solver = make_solver(fresh.model, robot, fresh.dt_sub, "mujoco", ground=ground)
    for name in MJW_DERIVED + (("geom_friction",) if ground else ()):
        a, b = (getattr(s.solver.mjw_model, name).numpy() for s in (sim, fresh))
        assert a.shape[0] == w, name
        assert np.allclose(a, b, rtol=1e-5, atol=1e-7), (name, np.abs(a - b).max())
    drawn = sim.solver.mjw_model.body_mass.numpy()
    assert np.abs(drawn[1] - drawn[0]).max() > 1e-3  # per world
    target = torch.full((w, robot.n_dof), 0.2, device=plant.device)
    z = torch.zeros(w, robot.n_dof, device=plant.device)
    runs = []
    pose, twist = (plant.base_pose, plant.base_twist) if ground else (None, None)
    for s in (sim, fresh):
        if ground:
            s.set_full_state(None, pose, twist, z, z)
        else:
            s.set_state(None, z, z)
        runs.append(torch.stack([s.step(target)[0] for _ in range(20)]))
    err = (runs[0] - runs[1]).abs().max().item()
    assert err < tol, err  # float32, the same kernels on the same values


def test_a_redraw_on_mujoco_warp_equals_a_solver_built_on_the_drawn_model(humanoid):
    """mujoco_warp (the GPU plants' solver, here on Warp's CPU device, on the stand): every randomised quantity but
    the floor's friction (the CPU's floor worlds are MuJoCo C threads; the GPU test below has it)."""
    torch.set_num_threads(1)
    plant = SimPlant(humanoid, WORLDS, RATE, 1, solver="mujoco", randomization=Randomization(seed=4))
    assert not plant.sim.refresh_graph  # no graphs on the CPU: the refresh stays eager
    _equals_a_solver_built_on_the_drawn_model(plant, humanoid, [[1, 2]])


def _cuda() -> bool:
    import warp as wp

    return wp.is_cuda_available()


@pytest.mark.skipif(not _cuda(), reason="CUDA graphs and the floor's batched mujoco_warp worlds need a GPU")
def test_on_a_gpu_a_captured_refresh_equals_a_solver_built_on_the_drawn_model(floating):
    """On the floor on a GPU with the solver's refresh replayed from a CUDA graph, CUDA's default (the plant's first
    draw captures it, the redraws replay it) and the steps from theirs: the floor friction too."""
    plant = SimPlant(floating, 16, RATE, 1, ground=True, device="cuda:0", randomization=Randomization(seed=4))
    assert plant.sim.refresh_graph
    # contacts found in another order by the GPU's atomics may round differently: a wider bound (not yet measured)
    _equals_a_solver_built_on_the_drawn_model(plant, floating, [[1, 2], [3, 5, 9]], ground=True, tol=1e-4)
    assert len(plant.sim._refresh_graphs) == 1
