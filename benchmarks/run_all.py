"""Run every benchmark in turn (`make bench`); each prints its own tables (see docs/benchmarks.md)."""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = ["bench_formfactors.py", "bench_forward.py", "bench_inverse.py", "bench_staircase.py"]

if __name__ == "__main__":
    failed = []
    for name in SCRIPTS:
        path = os.path.join(HERE, name)
        if not os.path.exists(path):
            continue
        print(f"=== {name}", flush=True)
        if subprocess.call([sys.executable, path]) != 0:
            failed.append(name)
    if failed:
        sys.exit(f"failed: {', '.join(failed)}")
