"""RViz and Foxglove configurations match what the world publishes."""

import json
import re
from pathlib import Path

import yaml

from flock_swarm.core.metrics import STEP_METRICS
from flock_swarm.contract import FRAME, MARKERS, METRICS, OBSTACLES, OBSTACLES_QOS
from flock_swarm.nodes.markers import OBSTACLES_NS

CONFIG = Path(__file__).resolve().parent.parent / 'config'


def test_rviz_shows_the_markers_in_the_world_frame():
    rviz = yaml.safe_load((CONFIG / 'swarm.rviz').read_text())
    manager = rviz['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == FRAME
    displays = {d['Name']: d for d in manager['Displays']}
    markers = displays['Swarm']
    assert markers['Class'] == 'rviz_default_plugins/MarkerArray'
    assert markers['Topic']['Value'] == '/' + MARKERS
    # The world publishes markers reliable (TELEMETRY_QOS): the display must subscribe reliable.
    assert markers['Topic']['Reliability Policy'] == 'Reliable'
    assert set(markers['Namespaces']) == {'agents', 'velocities', 'neighbours', 'leader',
                                          OBSTACLES_NS}
    # The obstacles come from their latched topic, once (not twice, from the markers too).
    assert markers['Namespaces'][OBSTACLES_NS] is False
    obstacles = displays['Obstacles']
    assert obstacles['Class'] == 'rviz_default_plugins/MarkerArray' and obstacles['Enabled']
    assert obstacles['Topic']['Value'] == '/' + OBSTACLES
    assert OBSTACLES_QOS.latched and OBSTACLES_QOS.reliable
    assert obstacles['Topic']['Durability Policy'] == 'Transient Local'
    assert obstacles['Topic']['Reliability Policy'] == 'Reliable'
    assert displays['Grid']['Class'] == 'rviz_default_plugins/Grid'


def test_foxglove_layout_panels_use_published_topics_and_keys():
    layout = json.loads((CONFIG / 'foxglove_layout.json').read_text())
    panels = layout['configById']
    three_d = next(v for k, v in panels.items() if k.startswith('3D!'))
    assert three_d['topics']['/' + MARKERS]['visible'] is True
    # A live view serves the markers (obstacles included), not the latched map: shown once.
    assert three_d['topics']['/' + OBSTACLES]['visible'] is False
    keys = set()
    for name, panel in panels.items():
        for path in panel.get('paths', []):
            topic = path['value'].split('.')[0]
            assert topic in ('/' + METRICS, '/leader/odom', '/agent_0/odom'), path
            keys.update(re.findall(r'key=="(\w+)"', path['value']))
    assert keys and keys <= set(STEP_METRICS)
    diag = next(v for k, v in panels.items() if k.startswith('DiagnosticStatusPanel!'))
    assert diag['topicToRender'] == '/' + METRICS
    # The headline leads (issue 24): a plot of the first values of /swarm/metrics, the
    # scenario's metrics.headline whatever the experiment, arranged before the other plots.
    first = [path['value'] for path in panels['Plot!headline']['paths']]
    assert first == [f'/{METRICS}.status[0].values[{k}].value' for k in (0, 1)]
    order = re.findall(r'"(Plot![\w-]+)"', json.dumps(layout['layout']))
    assert order[0] == 'Plot!headline'
    # Every panel in the arrangement exists.
    referenced = re.findall(r'"(\w+![\w-]+)"', json.dumps(layout['layout']))
    assert set(referenced) == set(panels)
