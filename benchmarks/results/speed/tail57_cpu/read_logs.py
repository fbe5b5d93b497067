"""Each run's clock from its log (`python read_logs.py OUT/*.log`): the whole command, the stamp of the fit's last line
before `done:` (the export starts there), `done:` (the parent's run files written), the splits replayed, `evaluation
done`, the last line (`wrote .../policy.onnx`: after the helpers were waited for), the tail (last - before done) and
the wait (last - evaluation done)."""
import re
import sys


def read(path):
    lines = open(path).read().splitlines()
    stamps = [(float(m[1]), ln) for ln in lines if (m := re.match(r"^\[ *([0-9.]+) s\] (.*)", ln))]

    def at(text):
        return next((t for t, ln in stamps if text in ln), float("nan"))

    done = at("done: ")
    i = next((k for k, (_, ln) in enumerate(stamps) if "done: " in ln), 0)
    before = stamps[i - 1][0] if i else float("nan")
    whole = next((ln for ln in lines if ln.startswith("whole command:")), "")
    if not whole:
        return "not finished"
    replayed, evaluated, last = at("splits replayed"), at("evaluation done"), stamps[-1][0] if stamps else float("nan")
    return (f"whole {whole.split()[2]:>6} s | before done {before:5.1f} | done {done:5.1f} | replayed {replayed:5.1f} | "
            f"evaluation done {evaluated:5.1f} | last {last:5.1f} | tail {last - before:4.1f} | "
            f"wait {last - evaluated:4.1f} | load {' '.join(whole.split()[-3:])}")


for p in sys.argv[1:]:
    print(f"{p.rsplit('/', 1)[-1][:-4]:7s} {read(p)}")
