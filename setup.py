"""ament_python package for the crane stiffness rig.

`colcon build` installs the console scripts below to <prefix>/lib/crane_stiffness/ (see setup.cfg), which is where
`ros2 run crane_stiffness <name>` looks; `pip install .` puts the same scripts on the venv's PATH.

`setup.py install` (what colcon runs) then compiles the model's numba kernels into their cache beside the installed
modules (crane_stiffness.model.kernel_cache), so the first start of crane_model after a build does not spend ~15 s
compiling. A staged install (``--root``, as when pip builds a wheel) skips it: the files move afterwards and numba's
cache is keyed by their modification times; `make install` compiles after `pip install` instead.
Set CRANE_STIFFNESS_NO_KERNEL_CACHE=1 to skip it.
"""
import os
import subprocess
import sys
from glob import glob

from setuptools import find_packages, setup
from setuptools.command.install import install

PACKAGE = 'crane_stiffness'

# The node executables: plain scripts in nodes_bin/ (installed to lib/crane_stiffness, see setup.cfg), each three
# lines into crane_stiffness.entry, which holds SIGINT/SIGTERM while the node's module imports. Not console_scripts:
# the script setuptools generates for those spends 0.1 s (seconds on a loaded machine) in importlib.metadata before
# any code of ours runs, and Ctrl-C in that time ended the node with a KeyboardInterrupt traceback.
NODES = (
    'load_program', 'crane_model', 'load_cell', 'lvdt', 'stiffness_estimator', 'session_recorder', 'session_player',
    # Real-hardware drivers and the device emulators that serve the simulated physics through the same protocols.
    'netft', 'modbus_lvdt', 'rdt_emulator', 'modbus_emulator',
)


class InstallAndCompileKernels(install):
    """``install``, then compile the kernels once in the installed package (see the module docstring)."""

    def run(self):
        super().run()
        if self.root or os.environ.get('CRANE_STIFFNESS_NO_KERNEL_CACHE'):
            return
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [self.install_lib,
                                                                         os.environ.get('PYTHONPATH')])))
        # From the install directory, so the installed package (not this source tree) is the one compiled.
        result = subprocess.run([sys.executable, '-m', 'crane_stiffness.model.kernel_cache'], env=env,
                                cwd=self.install_lib)
        if result.returncode:
            self.warn('compiling the model kernels failed; crane_model will compile them at its first start')


setup(
    name=PACKAGE,
    cmdclass={'install': InstallAndCompileKernels},
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='crane_stiffness maintainers',
    maintainer_email='crane-stiffness@example.org',
    description='Stiffness test rig for the six-wire parallel-link robot crane (ROS 2 Jazzy).',
    license='Apache-2.0',
    scripts=[f'nodes_bin/{name}' for name in NODES],
    entry_points={
        'console_scripts': ['crane-stiffness = crane_stiffness.cli:main'],
    },
)
