"""The headline of a run: the metrics a scenario says matter for it, and how they read.

A scenario names them in ``metrics.headline``: keys of the summary table
(:data:`~flock_swarm.core.summary.SUMMARY_KEYS`) that measure the run, in the order they are
to be read, with an optional ``metrics.claim``, what the paper claims of them (a short text:
``Su 2009 Fig. 6: -> 0 exponentially``). Without them the headline is ``eta`` and the
velocity mismatch, what every run printed before scenarios could choose.

Read from here: the last line of ``sim`` and ``swarm`` (:func:`result_line`), the progress
lines of ``sim`` and of the world (:func:`progress_text`) and the order of the values of
``/swarm/metrics`` (:func:`lead_with`: a viewer shows the headline first). The headline is
presentation only: no run, summary or time series depends on it, and :func:`run_mapping`
leaves it out of what keys a run's cache (a changed headline reruns nothing).
"""

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from flock_swarm.core.checks import text
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.summary import SUMMARY_KEYS, compared_metrics

#: The headline of a scenario that names none: what ``sim`` and ``swarm`` always printed.
DEFAULT_KEYS = ('eta', 'velocity_mismatch_max')
#: The keys of the ``metrics`` section that choose the headline (presentation, not the run).
HEADLINE_KEYS = ('headline', 'claim')
#: The longest claim [characters]: it is printed inside the one result line.
MAX_CLAIM = 100
#: How much of a bad value an error line shows.
_SHOWN = 60


@dataclass(frozen=True)
class Headline:
    """The metrics a run leads with.

    :ivar keys: summary keys, in the order they are read.
    :ivar claim: what the paper claims of them (``''``: no claim is printed).
    """

    keys: tuple[str, ...] = DEFAULT_KEYS
    claim: str = ''


@dataclass(frozen=True)
class Reading:
    """How one metric reads on a line.

    :ivar label: its name on the result line.
    :ivar spec: its format on the result line.
    :ivar unit: its unit (``''``: none shown).
    :ivar short: its name on a progress line.
    :ivar short_spec: its format on a progress line.
    :ivar live: its key among the values of ``/swarm/metrics`` (``None``: not published live).
    """

    label: str
    spec: str
    unit: str = ''
    short: str = ''
    short_spec: str = '.3g'
    live: str | None = None


#: The readings of the measures (a measure without one reads by its key), and of the counts
#: a result line ends with. eta and the velocity mismatch read as they always did.
READINGS: dict[str, Reading] = {
    'eta': Reading('eta', '.3f', '', 'eta', '.2f', 'eta'),
    'velocity_mismatch_max': Reading('velocity mismatch', '.3g', '', 'mismatch', '.3g',
                                     'velocity_mismatch_max'),
    'com_position_error': Reading('COM position error', '.3g', ' m', 'COM error', '.3g',
                                  'com_position_error'),
    'com_velocity_error': Reading('COM velocity error', '.3g', ' m/s', 'COM velocity error',
                                  '.3g', 'com_velocity_error'),
    'min_pair_distance': Reading('closest approach', '.3g', ' m', 'closest', '.3g',
                                 'min_pair_distance'),
    'collisions': Reading('collisions', 'd', '', 'collisions', 'd'),
    'components_final': Reading('components', 'd', '', 'components', 'g', 'components'),
    # Published live (/swarm/metrics) by a run with obstacles only.
    'obstacle_clearance_min': Reading('obstacle clearance', '.3g', ' m', 'clearance', '.3g',
                                      'obstacle_clearance'),
    'obstacle_penetrations': Reading('penetrations', 'd', '', 'penetrations', 'd'),
    'obstacle_collisions': Reading('obstacle collisions', 'd', '', 'obstacle collisions', 'd'),
    'missed_commands': Reading('missed commands', 'd'),
}


def headline_metrics() -> tuple[str, ...]:
    """Return the summary keys a headline may name: the measures of the run."""
    return compared_metrics()


def reading(key: str) -> Reading:
    """Return how ``key`` reads (a measure without a reading of its own: by its key)."""
    return READINGS.get(key, Reading(key, '.4g', '', key, '.3g', None))


def _shown(value: Any) -> str:
    shown = repr(value)
    return shown if len(shown) <= _SHOWN else shown[:_SHOWN] + '...'


def parse_headline(section: Mapping, prefix: str = 'metrics.') -> Headline:
    """Validate the headline keys of a scenario's ``metrics`` section.

    :param section: the ``metrics`` mapping (its other keys are not looked at).
    :param prefix: the section's dotted path, for error keys.
    :return: the headline (:data:`DEFAULT_KEYS` without ``headline``).
    :raises ScenarioError: naming the offending key.
    """
    claim = text(section.get('claim'), f'{prefix}claim', '')
    if len(claim) > MAX_CLAIM:
        raise ScenarioError(f'{prefix}claim', f'at most {MAX_CLAIM} characters (it is printed '
                            f'on the result line), got {len(claim)}')
    if not claim.isprintable():
        raise ScenarioError(f'{prefix}claim', 'must be one line of printable characters (it '
                            'is printed on the result line)')
    if 'headline' not in section:
        return Headline(DEFAULT_KEYS, claim)
    allowed = headline_metrics()
    expected = f'one of: {", ".join(allowed)}'
    raw = section['headline']
    if not isinstance(raw, list) or not raw:
        raise ScenarioError(f'{prefix}headline', f'expected a non-empty list of summary keys '
                            f'(one or more of: {", ".join(allowed)}), got {_shown(raw)}')
    summary_keys = {k.name for k in SUMMARY_KEYS}
    keys: list[str] = []
    for k, value in enumerate(raw):
        key = f'{prefix}headline[{k}]'
        if not isinstance(value, str):
            raise ScenarioError(key, f'expected a summary key ({expected}), got {_shown(value)}')
        if value not in allowed:
            what = ('a summary key that does not measure the run' if value in summary_keys
                    else 'not a summary key')
            raise ScenarioError(key, f'{_shown(value)} is {what} (expected {expected})')
        if value in keys:
            raise ScenarioError(key, f'{value} is named twice')
        keys.append(value)
    return Headline(tuple(keys), claim)


def _measure(value: float | None, spec: str, unit: str = '') -> str:
    """Return ``value`` formatted, or ``n/a`` for a measure the run did not take (null: it
    was stopped before its first recorded step)."""
    return 'n/a' if value is None else f'{value:{spec}}{unit}'


def _value(summary: Mapping, key: str) -> str:
    r = reading(key)
    return f'{r.label} = {_measure(summary.get(key, 0), r.spec, r.unit)}'


def result_line(summary: Mapping, headline: Headline, then: Sequence[str]) -> str:
    """Return how a run ended, leading with its headline.

    ``completed at t = 10 s: COM position error = 0.0834 m, COM velocity error = 0.0381 m/s
    (Su 2009 Fig. 6: -> 0 exponentially); collisions = 0, components = 1 (4.2 s wall)``.
    With the default headline and no claim it is the line every run printed before:
    ``completed at t = 10 s: eta = 0.000, velocity mismatch = 0.775, collisions = 0, ...``.

    :param summary: the run's ``summary.json``.
    :param headline: the scenario's headline.
    :param then: summary keys to give after the headline (those it holds are not repeated).
    :return: the line, without the command's ``[sim]`` prefix.
    """
    lead = ', '.join(_value(summary, key) for key in headline.keys)
    if headline.claim:
        lead += f' ({headline.claim})'
    rest = [_value(summary, key) for key in then if key not in headline.keys]
    wall = f'{summary.get("wall_time_s", 0):.1f} s wall'
    if headline.claim:
        # A semicolon ends what the claim speaks of.
        tail = f'; {", ".join(rest)} ({wall})' if rest else f'; {wall}'
    else:
        tail = f', {", ".join(rest)} ({wall})' if rest else f' ({wall})'
    return f'{summary["status"]} at t = {_measure(summary["t_final"], "g")} s: {lead}{tail}'


def progress_text(latest: Mapping, headline: Headline) -> str:
    """Return the headline's values in a progress line (``eta = 0.50  mismatch = 0.3``).

    :param latest: the metrics of the last measured step (``{}`` before the first: zeros).
    :param headline: the scenario's headline; its keys measured at every recorded step are
        shown (none of them: the default's).
    :return: the values, two spaces apart.
    """
    shown = [key for key in headline.keys if reading(key).live is not None] or DEFAULT_KEYS
    parts = []
    for key in shown:
        r = reading(key)
        parts.append(f'{r.short} = {latest.get(r.live, 0.0):{r.short_spec}}')
    return '  '.join(parts)


def lead_with(values: Mapping[str, Any], headline: Headline) -> dict[str, Any]:
    """Return the ``/swarm/metrics`` values with the headline's first, in its order.

    :param values: the values in the order the world measures them.
    :param headline: the scenario's headline (keys not published live keep their place).
    :return: the same values, reordered.
    """
    first = [r.live for r in map(reading, headline.keys) if r.live in values]
    return {**{key: values[key] for key in first},
            **{key: value for key, value in values.items() if key not in first}}


def run_mapping(raw: Mapping) -> dict:
    """Return a scenario mapping without its headline: what a run depends on.

    A cache of runs is keyed by the scenario as run; a headline chosen later must not make
    its runs look new. The ``metrics`` section goes with it when the headline was all it held.

    :param raw: the scenario mapping as run.
    :return: a shallow copy without ``metrics.headline`` and ``metrics.claim``.
    """
    out = dict(raw)
    metrics = out.get('metrics')
    if not isinstance(metrics, dict) or not any(key in metrics for key in HEADLINE_KEYS):
        return out
    rest = {key: value for key, value in metrics.items() if key not in HEADLINE_KEYS}
    if rest:
        out['metrics'] = rest
    else:
        del out['metrics']
    return out
