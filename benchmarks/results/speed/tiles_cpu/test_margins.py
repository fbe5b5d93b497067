"""The largest |tiles - torch| / max |torch| over the buffers of the cases of tests/learn/test_tile_mlp.py (its
bound: 1e-5)."""
import sys, torch
sys.path.insert(0, "tests/learn")  # from the repository root, PYTHONPATH=.
import test_tile_mlp as T
for hidden, batch in [(T.HIDDEN, 19), ((256, 128, 64), 64)]:
    policy = T._policy("cpu", hidden); policy.mlp[-1].weight.data.mul_(10)
    g = torch.Generator().manual_seed(2)
    obs = (torch.randn(batch, 4 * T.N, generator=g) * 4)
    grads = [torch.randn(batch, T.N, generator=g) for _ in range(2)]
    ref, tile = (T._one_step(t, policy, obs, grads[0], grads[1], True) for t in (False, True))
    worst = max(((a - b).abs().max() / b.abs().max()).item() for a, b in zip([tile[0], tile[1]] + tile[2] + tile[3] + tile[4], [ref[0], ref[1]] + ref[2] + ref[3] + ref[4]))
    print(hidden, "one step worst |diff|/max", worst)
for batch, both in [(8, False), (37, True)]:
    ref, tile = T._chain(False, "cpu", batch, both), T._chain(True, "cpu", batch, both)
    w = max([((tile[i] - ref[i]).abs().max() / ref[i].abs().max()).item() for i in (0, 1)] + [((tile[2][k] - ref[2][k]).abs().max() / ref[2][k].abs().max()).item() for k in ref[2]])
    print("chain", batch, both, "worst |diff|/max", w)
