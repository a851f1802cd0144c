"""Start-up benchmark: time from launch to program start, cold and warm.

Every node of rig.launch.py is started at the same instant, the way `ros2 launch` starts them (as `ros2 run` runs
each executable, from a colcon install tree; crane_stiffness.launcher.rig.start_rig), and the time is taken from
that instant to load_program's state 'running' arriving at an observer in this process. load_program starts the
program only once the rig is ready (the model's prediction, both sensor streams, every reader subscribed), so this
is the time until a load can be applied.

- cold: the first launch from a fresh `colcon build` (the build puts the model's compiled kernels into the install
  tree: copied from the cache `make install` compiled in .venv when the files are the same, else compiled,
  crane_stiffness.model.kernel_cache); nothing of the package has run from that tree before;
- warm: later launches from the same tree;
- no kernel cache (an install tree as built without the cache): a copy of the fresh tree without the compiled kernels,
so
  crane_model compiles them at its start.

The OS page cache cannot be dropped without root, so "cold" means cold for the package, not for the disk. The
machine's 1-minute load average before each launch is reported beside it: six Python processes importing rclpy,
numpy and numba at once are CPU-bound, so on a shared machine the absolute times follow its load.

Run: .venv/bin/python benchmarks/bench_startup.py [--warm-runs 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
# The observer below discovers the nodes as quickly as they discover each other (crane_stiffness.rosnode.discovery).
from crane_stiffness.rosnode.discovery import use_quick_discovery  # noqa: E402

use_quick_discovery()

KERNEL_CACHE = ('*.nbi', '*.nbc')
LOADS: list[float] = []  # load average before each launch, in order: cold, warm..., no cache...


def launch_to_program_start(install: Path, log_dir: Path, timeout_s: float = 180.0) -> float:
    """Seconds from starting every rig node at once to the program's start (then everything is stopped)."""
    LOADS.append(round(os.getloadavg()[0], 2))
    import rclpy

    from crane_stiffness.launcher import rosrun
    from crane_stiffness.launcher.rig import Observer, start_rig, wait_for_program_start
    env = rosrun.install_environment(install)
    share = rosrun.installed_config(install)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    observer = Observer(context=ctx)
    try:
        with rosrun.Processes(env, log_dir) as procs:
            launched = time.monotonic()
            start_rig(procs, share, 'side_force', 'bench_startup', log_dir / 'bags', ready_timeout_s=timeout_s)
            wait_for_program_start(observer, procs, timeout_s + 10)
            return observer.running_at - launched
    finally:
        observer.destroy_node()
        rclpy.shutdown(context=ctx)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--warm-runs', type=int, default=3, help='launches after the first one')
    ap.add_argument('--no-cache-runs', type=int, default=1, help='launches without the compiled kernels')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)

    from crane_stiffness.launcher import rosrun
    with tempfile.TemporaryDirectory(prefix='bench_startup_') as tmp:
        ws = Path(tmp)
        src = ws / 'src' / 'crane_stiffness'
        shutil.copytree(REPO, src, ignore=shutil.ignore_patterns('.venv', '.git', 'build', 'install', 'log', 'out',
                                                                 '__pycache__', 'bags', '*.egg-info'))
        t0 = time.monotonic()
        rosrun.colcon_build(src, ws / 'build', ws / 'install', ws / 'log')
        build_s = time.monotonic() - t0
        print(f'colcon build (with the kernel cache step): {build_s:.1f} s', flush=True)
        nocache = ws / 'install_nocache'
        shutil.copytree(ws / 'install', nocache, ignore=shutil.ignore_patterns(*KERNEL_CACHE), symlinks=True)
        cold = launch_to_program_start(ws / 'install', ws / 'logs' / 'cold')
        print(f'cold (first launch after the build): {cold:.1f} s', flush=True)
        warm = []
        for i in range(args.warm_runs):
            warm.append(launch_to_program_start(ws / 'install', ws / 'logs' / f'warm{i}'))
            print(f'warm #{i + 1}: {warm[-1]:.1f} s', flush=True)
        no_cache = []
        for i in range(args.no_cache_runs):
            run_dir = ws / f'install_nocache_{i}'
            shutil.copytree(nocache, run_dir, symlinks=True)
            no_cache.append(launch_to_program_start(run_dir, ws / 'logs' / f'nocache{i}'))
            print(f'no kernel cache #{i + 1}: {no_cache[-1]:.1f} s', flush=True)
    result = {
        'build_s': build_s, 'cold_s': cold, 'warm_s': warm, 'warm_median_s': statistics.median(warm) if warm else None,
        'cold_minus_warm_s': cold - statistics.median(warm) if warm else None,
        'cold_over_warm': cold / statistics.median(warm) if warm else None,
        'no_kernel_cache_s': no_cache, 'load_average_before': LOADS, 'cpus': os.cpu_count(), 'goal_s': 5.0,
        'met': cold <= 5.0 and all(w <= 5.0 for w in warm),
    }
    print(json.dumps(result, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
