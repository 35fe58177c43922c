"""Obstacles in the ROS nodes: a lockstep run equals ``sim`` bit for bit in every layout, the
world publishes the map latched and in ``/swarm/markers``, and ``analyze`` of the bag alone
gives the obstacle metrics and draws the obstacles."""

import json

import numpy as np
import pytest
from flock_swarm.bag import BagReader
from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.nodes.markers import OBSTACLES_NS
from flock_swarm.testing import assert_matches_sim
from test_network_ros import LAYOUTS as NETWORK_LAYOUTS, RUN_TIMEOUT
from test_obstacles import obstacle_pixels

#: A small demo swarm packed within each other's radius between a wall (x = -0.5) and a disc
#: (centre (4, 9.5), radius 1): the agents near them feel the beta term from the first step.
DEMO = ['n_agents=8', 'informed.count=3', 'duration=0.4', 'record_every=3',
        'initial.position_box=[[0, 8], [0, 8]]',
        'obstacles={walls: [{point: [-0.5, 0], normal: [1, 0]}], '
        'spheres: [{centre: [4, 9.5], radius: 1}]}']
#: The layouts of a ROS run (keyword arguments of assert_matches_sim): one process, and the
#: agents in one container process.
LAYOUTS = {name: NETWORK_LAYOUTS[name] for name in ('one process', 'processes, container')}


@pytest.mark.ros
@pytest.mark.parametrize('layout', LAYOUTS)
def test_a_run_with_obstacles_matches_sim_in_every_layout(tmp_path, ros_domain, layout):
    run = assert_matches_sim('demo', tmp_path / 'run', DEMO, domain_id=ros_domain, atol=0,
                             timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    s = run.summary
    # The term acted: agents came within the sensing range r' = 1.2 * 0.6 * 3.3 m.
    assert 0.0 < s['obstacle_clearance_min'] < 1.2 * 0.6 * 3.3
    assert s['obstacle_penetrations'] == 0
    series = run.timeseries()
    assert series['obstacle_clearance'].shape == series['t'].shape
    assert np.isfinite(series['obstacle_clearance']).all()
    if layout != 'one process':
        return
    # The bag holds the map, latched at t = 0: a wall (a slab) and a disc, in that order of
    # the markers as in the map (spheres first).
    reader = BagReader(tmp_path / 'run' / 'bag')
    assert reader.topics()['/swarm/obstacles'] == 'visualization_msgs/msg/MarkerArray'
    (record, msg), = reader.decoded('/swarm/obstacles')
    assert record.log_time_ns == 0
    assert [(m.ns, m.id, m.type) for m in msg.markers] == [
        (OBSTACLES_NS, 0, 3), (OBSTACLES_NS, 1, 1)]  # CYLINDER (a 2-D disc), CUBE (a wall)
    disc, wall = msg.markers
    assert (disc.pose.position.x, disc.pose.position.y, disc.scale.x) == (4.0, 9.5, 2.0)
    assert wall.pose.position.x < -0.5 and wall.pose.orientation.w == pytest.approx(1.0)
    # Every /swarm/markers message draws them too.
    for _, markers in reader.decoded('/swarm/markers'):
        assert [m.ns for m in markers.markers][4:] == [OBSTACLES_NS, OBSTACLES_NS]
    # analyze, from the bag alone: the same obstacle metrics, sim's run, the map drawn.
    out = tmp_path / 'analysis'
    assert analyze_main([str(tmp_path / 'run' / 'bag'), '--out', str(out), '--verify',
                         '--quiet', '--no-anim']) == 0
    ours = json.loads((out / 'summary.json').read_text())
    assert ours['verify_passed'] is True
    for key in ('obstacle_clearance_min', 'obstacle_penetrations', 'obstacle_collisions'):
        assert ours[key] == s[key], key
    assert obstacle_pixels(out / 'trajectories.png') > 100
    assert obstacle_pixels(out / 'snapshots.png') > 100


@pytest.mark.parametrize('dim', [2, 3])
def test_markers_with_obstacles_written_as_cdr_are_the_rclpy_markers(dim):
    """The world's fast path draws the obstacles as the rclpy markers do; a wall's slab lies
    behind its surface with its x axis along the normal."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from scipy.spatial.transform import Rotation
    from visualization_msgs.msg import MarkerArray

    from flock_swarm.core.graphs import disk_graph
    from flock_swarm.core.obstacles import parse_obstacles
    from flock_swarm.nodes.markers import (WALL_THICKNESS, obstacle_markers, swarm_markers,
                                           swarm_markers_cdr)

    class Law:
        name, accepts_obstacles, d = 'law', True, 3.0
    rest = [0.0] * (dim - 2)
    normals = [[0.6, 0.8, *rest], [-1.0, 0.0, *rest], [1.0, 0.0, *rest], [0.0, -1.0, *rest]]
    spec = parse_obstacles({'spheres': [{'centre': [1.0, 2.0, *rest], 'radius': 0.5}],
                            'walls': [{'point': [3.0, -1.0, *rest], 'normal': n}
                                      for n in normals]}, dim, Law())
    rng = np.random.default_rng(dim)
    q, p = rng.uniform(0.0, 10.0, (12, dim)), rng.normal(size=(12, dim))
    edges, informed = disk_graph(q, 4.0), rng.random(12) < 0.3
    typed = swarm_markers(q, p, q[0], informed, edges, Time(sec=1), 'world', 0.3, spec)
    ours = swarm_markers_cdr(q, p, q[0], informed, edges, 1_000_000_000, 'world', 0.3, spec)
    assert deserialize_message(ours, MarkerArray) == \
        deserialize_message(serialize_message(typed), MarkerArray)
    alone = obstacle_markers(spec, dim, Time(sec=1), 'world').markers
    assert typed.markers[4:] == alone and len(alone) == 5
    for marker, normal in zip(alone[1:], normals):
        o = marker.pose.orientation
        x_axis = Rotation.from_quat([o.x, o.y, o.z, o.w]).apply([1.0, 0.0, 0.0])
        assert np.allclose(x_axis, (normal + [0.0] * (3 - dim)), atol=1e-12)
        centre = np.array([marker.pose.position.x, marker.pose.position.y,
                           marker.pose.position.z])
        surface = np.array([3.0, -1.0, 0.0])
        assert np.dot(centre - surface, x_axis) == pytest.approx(-WALL_THICKNESS / 2)
