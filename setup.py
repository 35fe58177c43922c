from glob import glob

from setuptools import find_packages
from setuptools import setup

package_name = 'flock_swarm'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config',
         glob('config/*.yaml') + glob('config/*.rviz') + glob('config/*.json')
         + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*_launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='flock_swarm developers',
    maintainer_email='dev@flock-swarm.invalid',
    description=(
        'Flocking swarm behind a virtual leader: agent, leader and world nodes, '
        'a reference simulator, and MCAP recording.'
    ),
    license='Apache-2.0',
    tests_require=['pytest'],
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'sim = flock_swarm.sim:main',
            'swarm = flock_swarm.runner:main',
            'leader = flock_swarm.nodes.leader:main',
            'agent = flock_swarm.nodes.agent:main',
            'agents = flock_swarm.nodes.agent:container_main',
            'world = flock_swarm.nodes.world:main',
            'replay = flock_swarm.replay:main',
            'analyze = flock_swarm.analyze:main',
            'foxglove_server = flock_swarm.nodes.foxglove_server:main',
        ],
    },
)
