"""torch._dynamo imported as the fit imports it now (after the set-up's freeze, the collector on) or within the set-up
(the collector off, frozen after): the import's seconds, the collections during it, the objects a later full
collection walks and its seconds."""
import gc, sys, time
mode = sys.argv[1]
import torch, numpy, warp, newton  # what the fit has imported before its first optimiser
import wresdyn.fit.gradfit, wresdyn.fit.hybrid
D = []
def cb(phase, info, t=[0.0]):
    if phase == "start":
        t[0] = time.perf_counter()
    else:
        D.append((info["generation"], time.perf_counter() - t[0]))
gc.disable()
gc.collect()
if mode == "after_freeze":
    gc.freeze(); gc.enable()
gc.callbacks.append(cb)
t = time.perf_counter()
import torch._dynamo
dt = time.perf_counter() - t
if mode == "in_setup":
    gc.freeze(); gc.enable()
gc.callbacks.remove(cb)
n = len(gc.get_objects())
t = time.perf_counter(); gc.collect(); full = time.perf_counter() - t
print(f"{mode:12s}: import {dt:.2f} s, {len(D)} collections in it {sum(d for _, d in D):.2f} s "
      f"({sum(g == 2 for g, _ in D)} full); then {n} objects tracked, a full collection {full:.3f} s", flush=True)
