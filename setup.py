"""ament_python package for the crane stiffness rig.

`colcon build` installs the console scripts below to <prefix>/lib/crane_stiffness/ (see setup.cfg), which is where
`ros2 run crane_stiffness <name>` looks; `pip install .` puts the same scripts on the venv's PATH.

`setup.py install` (what colcon runs) then compiles the model's numba kernels into their cache beside the installed
modules (crane_stiffness.model.kernel_cache), so the first start of crane_model after a build does not spend ~15 s
compiling. When the interpreter running the build has the same package installed with its kernels compiled (`make
install`'s .venv, whose colcon builds the demo's and the tests' install trees), that cache is copied instead: numba
keys it by the source files' contents, not their paths, so the kernels are compiled once for both. A staged install
(``--root``, as when pip builds a wheel) skips it: a wheel carries no machine code compiled for one CPU; `make install`
compiles after `pip install` instead. Set CRANE_STIFFNESS_NO_KERNEL_CACHE=1 to skip it.
"""
import ast
import os
import subprocess
import sys
import sysconfig
from glob import glob

from setuptools import find_packages, setup
try:
    from setuptools.command.build_scripts import build_scripts
except ImportError:  # setuptools without its own (it uses distutils')
    from distutils.command.build_scripts import build_scripts
from setuptools.command.install import install

PACKAGE = 'crane_stiffness'

# The node executables: plain scripts in nodes_bin/ (installed to lib/crane_stiffness, see setup.cfg), each three
# lines into crane_stiffness.rosnode.entry, which holds SIGINT/SIGTERM while the node's module imports. Not
# console_scripts:
# the script setuptools generates for those spends 0.1 s (seconds on a loaded machine) in importlib.metadata before
# any code of ours runs, and Ctrl-C in that time ended the node with a KeyboardInterrupt traceback. The one list of
# the package's nodes is crane_stiffness.nodes.NODES (read here without importing the package): a node is
# crane_stiffness/nodes/<name>.py and nodes_bin/<name>, and a nodes_bin/ that lists other names stops the build.
HERE = os.path.dirname(os.path.abspath(__file__))


def read_nodes():
    """crane_stiffness.nodes.NODES, read from the source (setup.py imports nothing of the package)."""
    path = os.path.join(HERE, PACKAGE, 'nodes', '__init__.py')
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and any(getattr(t, 'id', None) == 'NODES' for t in stmt.targets):
            return tuple(ast.literal_eval(stmt.value))
    raise RuntimeError(f'{path}: no NODES')


NODES = read_nodes()
if sorted(os.listdir(os.path.join(HERE, 'nodes_bin'))) != sorted(NODES):
    raise RuntimeError(f'nodes_bin/ holds {sorted(os.listdir(os.path.join(HERE, "nodes_bin")))}, '
                       f'crane_stiffness.nodes.NODES names {sorted(NODES)}: they must be the same')


# A signal in the first milliseconds of a Python process, while the interpreter itself starts (before any line of
# ours, in its `site` import), ends it with "Fatal Python error ... KeyboardInterrupt" or kills it (-2): `ros2 launch`
# starts every node at once and a Ctrl-C then reaches all of them. So each built node script is a small sh prologue
# that ignores SIGINT/SIGTERM and execs the interpreter on the same file: an ignored signal stays ignored through exec
# and the interpreter's start, until crane_stiffness.rosnode.entry installs its own handlers (from then on a signal is
# noted
# and the node ends cleanly). A signal in that window is dropped; launch forwards SIGINT once more and escalates to
# SIGTERM after 5 s, which the node then ends on. To Python the prologue is a string literal.
SH_PROLOGUE = '''#!/bin/sh
\'\'\':'
trap '' INT TERM
exec {python} "$0" "$@"
\'\'\'
'''


class BuildNodeScripts(build_scripts):
    """``build_scripts``, then each node script (its shebang already the interpreter's) behind SH_PROLOGUE."""

    def run(self):
        super().run()
        for name in NODES:
            path = os.path.join(self.build_dir, name)
            with open(path) as f:
                shebang, body = f.readline(), f.read()
            if not shebang.startswith('#!') or shebang.startswith('#!/bin/sh'):
                continue
            python = shebang[2:].strip()
            if os.path.isabs(python):
                python = "'" + python.replace("'", "'\\''") + "'"
            else:  # a wheel's '#!python', rewritten by pip on install: the scripts go beside the interpreter
                python = '"${0%/*}/python"'
            with open(path, 'w') as f:
                f.write(SH_PROLOGUE.format(python=python) + body)


class InstallAndCompileKernels(install):
    """``install``, then compile the kernels once in the installed package (see the module docstring)."""

    def run(self):
        super().run()
        if self.root or os.environ.get('CRANE_STIFFNESS_NO_KERNEL_CACHE'):
            return
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [self.install_lib,
                                                                         os.environ.get('PYTHONPATH')])))
        # From the install directory, so the installed package (not this source tree) is the one compiled; seeded
        # with the cache of this interpreter's own installation of the package if its files are the same (colcon's
        # prefix_override/sitecustomize.py moves sys.prefix to the install prefix and keeps the real one aside).
        prefix = getattr(sys, 'real_prefix', sys.prefix)
        site = sysconfig.get_paths(vars={'base': prefix, 'platbase': prefix})['purelib']
        result = subprocess.run([sys.executable, '-m', 'crane_stiffness.model.kernel_cache', '--seed-from', site],
                                env=env, cwd=self.install_lib)
        if result.returncode:
            self.warn('compiling the model kernels failed; crane_model will compile them at its first start')


setup(
    name=PACKAGE,
    cmdclass={'install': InstallAndCompileKernels, 'build_scripts': BuildNodeScripts},
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    # the live view's page (plain HTML/JS/CSS, served by the live_view node)
    package_data={PACKAGE + '.view': ['web/*'], PACKAGE + '.rosnode': ['fastdds_discovery.xml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.launch.py'))),
        ('share/' + PACKAGE + '/foxglove', sorted(glob('foxglove/*.json'))),
        # rosdep keys for what only PyPI has (docs/running.md: rosdep reads it from the source tree, before a build)
        ('share/' + PACKAGE + '/rosdep', ['rosdep/crane_stiffness.yaml']),
    ],
    install_requires=['setuptools'],
    # `crane-stiffness campaign analyze --scheduler tcp://...`: per-session analyses on a Dask cluster
    extras_require={'dask': ['dask[distributed]==2026.8.0']},
    zip_safe=False,
    maintainer='crane_stiffness maintainers',
    maintainer_email='crane-stiffness@example.org',
    description='Stiffness test rig for the six-wire parallel-link robot crane (ROS 2 Jazzy).',
    license='Apache-2.0',
    scripts=[f'nodes_bin/{name}' for name in NODES],
    entry_points={
        'console_scripts': ['crane-stiffness = crane_stiffness.cli.main:main'],
    },
)
