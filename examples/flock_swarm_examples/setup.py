from glob import glob

from setuptools import find_packages
from setuptools import setup

package_name = 'flock_swarm_examples'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='flock_swarm developers',
    maintainer_email='dev@flock-swarm.invalid',
    description='Cucker-Smale flocking and a figure-eight leader as flock_swarm plugins.',
    license='Apache-2.0',
    tests_require=['pytest'],
    python_requires='>=3.10',
    entry_points={
        # flock_swarm finds laws and leader models by these names (protocol.name and
        # leader.model in a scenario); the name must equal the class's `name`.
        'flock_swarm.laws': [
            'cucker_smale = flock_swarm_examples.cucker_smale:CuckerSmale',
        ],
        'flock_swarm.leaders': [
            'figure_eight = flock_swarm_examples.figure_eight:FigureEight',
        ],
    },
)
