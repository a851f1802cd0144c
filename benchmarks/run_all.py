"""`make bench`: every benchmark, one after the other (they share the machine, so never in parallel).

Each prints its figures and the ratio to the baseline it measures in the same run; the JSON goes to out/bench/.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / 'out' / 'bench'
BENCHMARKS = [
    ('bench_solver.py', []),
    ('bench_bag_decode.py', []),
    ('bench_analyze.py', []),
    ('bench_rig.py', []),
    ('bench_startup.py', []),
    ('bench_soak.py', []),   # 10 minutes of the whole rig: every node's memory growth
]


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    failed = []
    for script, args in BENCHMARKS:
        print(f'=== {script}', flush=True)
        argv = [sys.executable, str(HERE / script), *args]
        if script in ('bench_solver.py', 'bench_rig.py', 'bench_startup.py', 'bench_soak.py'):
            argv += ['--json', str(OUT / script.replace('.py', '.json'))]
        if subprocess.run(argv).returncode != 0:
            failed.append(script)
    if failed:
        print('targets missed or errors in: ' + ', '.join(failed))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
