from glob import glob

from setuptools import find_packages
from setuptools import setup

package_name = 'flock_swarm'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config',
         glob('config/*.yaml') + glob('config/*.rviz') + glob('config/*.json')
         + glob('config/*.xml')),
        ('share/' + package_name + '/config/sweeps', glob('config/sweeps/*.yaml')),
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
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'sim = flock_swarm.cli.sim:main',
            'swarm = flock_swarm.cli.swarm:main',
            'leader = flock_swarm.nodes.leader:main',
            'agent = flock_swarm.nodes.agent:main',
            'agents = flock_swarm.nodes.agent:container_main',
            'world = flock_swarm.nodes.world:main',
            'replay = flock_swarm.cli.replay:main',
            'analyze = flock_swarm.cli.analyze:main',
            'sweep = flock_swarm.cli.sweep:main',
            'foxglove_server = flock_swarm.nodes.foxglove_server:main',
        ],
        # The built-in laws, leader models and plants, registered exactly as a user's package
        # registers its own (docs/extending.md): one registry, one code path.
        'flock_swarm.laws': [
            'olfati_saber_2006 = flock_swarm.core.laws.su2009:OlfatiSaber2006',
            'su_informed = flock_swarm.core.laws.su2009:SuInformed',
            'su_accel = flock_swarm.core.laws.su2009:SuAccel',
            'su_informed_accel = flock_swarm.core.laws.su2009:SuInformedAccel',
            'os2003_sink = flock_swarm.core.laws.os2003:OlfatiSaber2003Sink',
            'zhou_pseudo_leader = flock_swarm.core.laws.zhou2012:ZhouPseudoLeader',
            'yu_pinning_observer = flock_swarm.core.laws.yu2010:YuPinningObserver',
            'jadbabaie_leader = flock_swarm.core.laws.jadbabaie2003:JadbabaieLeader',
            'linear_consensus = flock_swarm.core.laws.linear:LinearConsensus',
        ],
        'flock_swarm.leaders': [
            'constant_velocity = flock_swarm.core.leaders.models:ConstantVelocity',
            'constant_acceleration = flock_swarm.core.leaders.models:ConstantAcceleration',
            'lorenz = flock_swarm.core.leaders.models:Lorenz',
            'lu = flock_swarm.core.leaders.models:Lu',
            'linear = flock_swarm.core.leaders.models:Linear',
            'sink = flock_swarm.core.leaders.models:Sink',
        ],
        'flock_swarm.plants': [
            'double_integrator = flock_swarm.core.plants.models:DoubleIntegrator',
            'velocity_lag = flock_swarm.core.plants.models:VelocityLag',
            'unicycle = flock_swarm.core.plants.models:Unicycle',
        ],
        # The launch-free testing API's fixtures (ros_domain, flock_swarm_run...) for every
        # pytest run in an environment holding flock_swarm.
        'pytest11': ['flock_swarm = flock_swarm.testing'],
    },
)
