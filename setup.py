"""ament_python package for the crane stiffness rig.

`colcon build` installs the console scripts below to <prefix>/lib/crane_stiffness/ (see setup.cfg), which is where
`ros2 run crane_stiffness <name>` looks; `pip install .` puts the same scripts on the venv's PATH.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'crane_stiffness'

NODES = {
    'load_program': 'crane_stiffness.nodes.load_program:main',
    'crane_model': 'crane_stiffness.nodes.crane_model:main',
    'load_cell': 'crane_stiffness.nodes.load_cell:main',
    'lvdt': 'crane_stiffness.nodes.lvdt:main',
    'stiffness_estimator': 'crane_stiffness.nodes.stiffness_estimator:main',
    'session_recorder': 'crane_stiffness.nodes.session_recorder:main',
    'session_player': 'crane_stiffness.nodes.session_player:main',
    # Real-hardware drivers and the device emulators that serve the simulated physics through the same protocols.
    'netft': 'crane_stiffness.nodes.netft:main',
    'modbus_lvdt': 'crane_stiffness.nodes.modbus_lvdt:main',
    'rdt_emulator': 'crane_stiffness.nodes.rdt_emulator:main',
    'modbus_emulator': 'crane_stiffness.nodes.modbus_emulator:main',
}

setup(
    name=PACKAGE,
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
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in NODES.items()]
        + ['crane-stiffness = crane_stiffness.cli:main'],
    },
)
