"""Install rules for the ament_python package hexapod_vibration."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'hexapod_vibration'
SHARE = f'share/{PACKAGE}'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (SHARE, ['package.xml']),
        (f'{SHARE}/config', sorted(glob('config/*.yaml'))),
        (f'{SHARE}/config/scenarios', sorted(glob('config/scenarios/*.yaml'))),
        (f'{SHARE}/config/sweeps', sorted(glob('config/sweeps/*.yaml'))),
        (f'{SHARE}/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='hexapod_vibration maintainers',
    maintainer_email='hexapod-vibration@example.com',
    description='Adaptive notch vibration suppression on a simulated pointing hexapod.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'pph_driver = hexapod_vibration.nodes.pph_driver:main',
            'notch_controller = hexapod_vibration.nodes.notch_controller:main',
            'pointing_controller = hexapod_vibration.nodes.pointing_controller:main',
            'pph_graph = hexapod_vibration.nodes.pph_graph:main',
            'pph_recorder = hexapod_vibration.nodes.recorder:main',
            'experiment = hexapod_vibration.tools.experiment:main',
            'analyze = hexapod_vibration.tools.analyze:main',
            'hexapod_bench = hexapod_vibration.bench.core_bench:main',
            'sweep = hexapod_vibration.tools.sweep:main',
        ],
    },
)
