from glob import glob
import os
import sys
import sysconfig

from setuptools import Extension
from setuptools import find_packages
from setuptools import setup
from setuptools.command.build_ext import build_ext

package_name = 'flock_swarm'


def _rcl_prefixes() -> list[str]:
    """Return the prefixes that may hold the ROS wheels' include/ and lib/ (the
    interpreter's, then AMENT_PREFIX_PATH's)."""
    prefixes = [sys.prefix, sysconfig.get_config_var('prefix') or sys.prefix]
    prefixes += [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return list(dict.fromkeys(prefixes))


def rclbatch_extension() -> tuple[list[Extension], str | None]:
    """Return the C extension (compiled message path, docs/performance.md) and ``None``, or no
    extension and why: without rcl's headers and libraries the nodes use pure rclpy."""
    for prefix in _rcl_prefixes():
        include, lib = os.path.join(prefix, 'include'), os.path.join(prefix, 'lib')
        if os.path.isfile(os.path.join(include, 'rcl', 'rcl', 'rcl.h')) \
                and os.path.isfile(os.path.join(lib, 'librcl.so')):
            # The wheels put each package's headers in include/<package>/<package>/ (ROS 2's
            # layout since Humble): rcl's include the others', so every one is on the path.
            dirs = sorted(entry.path for entry in os.scandir(include)
                          if entry.is_dir() and not entry.name.startswith('python'))
            return [Extension(
                'flock_swarm._rclbatch', ['flock_swarm/_rclbatch.c'],
                include_dirs=dirs, library_dirs=[lib], libraries=['rcl', 'rmw', 'rcutils'],
                runtime_library_dirs=[lib], extra_compile_args=['-std=c11', '-O2'],
                optional=True)], None
    return [], 'rcl headers and librcl.so not found under ' + ', '.join(_rcl_prefixes())


class OptionalBuildExt(build_ext):
    """build_ext that never fails the installation: an extension it cannot build is left
    out with one line saying why (the nodes fall back to pure rclpy)."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # noqa: B902 (no compiler at all is a DistutilsError)
            self._skipped(exc)

    def build_extension(self, ext) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:  # noqa: B902
            self._skipped(exc)

    @staticmethod
    def _skipped(exc: Exception) -> None:
        reason = ' '.join(str(exc).split())[:300]
        print(f'flock_swarm: C message path not built ({reason}); the nodes use pure rclpy',
              file=sys.stderr)


EXT_MODULES, EXT_SKIPPED = rclbatch_extension()
if EXT_SKIPPED is not None:
    print(f'flock_swarm: C message path not built ({EXT_SKIPPED}); the nodes use pure rclpy',
          file=sys.stderr)

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # The robot models of the physics-engine world (flock_swarm/engine/*.xml, MJCF).
    package_data={package_name: ['py.typed', 'engine/*.xml']},
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
    ext_modules=EXT_MODULES,
    cmdclass={'build_ext': OptionalBuildExt},
    zip_safe=False,
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
            # A flocking agent on a real robot, behind the safety layer (docs/robots.md).
            'robot_agent = flock_swarm.nodes.robot_agent:main',
            # Simulated robots: the physics engine behind each robot's cmd_vel and odom.
            'engine_robots = flock_swarm.nodes.engine_robots:main',
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
