"""The scenario's ``network:`` section: delay, loss, noise and sampling period, in steps.

:func:`parse_network` reads the section into a :class:`NetworkSpec` (``docs/network.md``);
:mod:`flock_swarm.core.network` applies it to a run.
"""

from dataclasses import dataclass

import numpy as np

from flock_swarm.core.checks import choice, integer, mapping, number, only
from flock_swarm.core.errors import ScenarioError

DELAY_LAWS = ('fixed', 'uniform', 'geometric')
LOSS_MODELS = ('bernoulli', 'gilbert_elliott')
#: The delay models of the consensus literature (Olfati-Saber & Murray 2004, Section VIII).
DELAY_MODELS = ('communication', 'input')
#: What an agent does with the age of what it holds: ``none`` (uses it as it is) or
#: ``predict`` (extrapolates it to the current step, docs/network.md).
COMPENSATIONS = ('none', 'predict')
CHANNEL_KEYS = ('delay', 'loss', 'noise', 'period')
NETWORK_KEYS = (*CHANNEL_KEYS, 'leader', 'model', 'max_age', 'compensation')
#: A time in seconds is a whole number of steps when ``|x / dt - round(x / dt)|`` is below it.
STEP_TOLERANCE = 1e-9
#: The longest history kept [steps]: the window holds the agents' states and the links of
#: every step within it, so a longer one would take memory for information the run drops.
MAX_WINDOW = 100_000


@dataclass(frozen=True)
class Delay:
    """The delay of each message, in steps.

    :ivar law: ``fixed`` (``low``), ``uniform`` (an integer in ``[low, high]``) or
        ``geometric`` (``P(d) = p (1 - p)^d``, truncated at ``high``: the excess lands on it).
    :ivar low: the fixed delay, or the smallest.
    :ivar high: the largest delay.
    :ivar p: the geometric law's parameter, ``1 / (1 + mean / dt)``.
    """

    law: str = 'fixed'
    low: int = 0
    high: int = 0
    p: float = 1.0

    def draw(self, u: np.ndarray) -> np.ndarray:
        """Return the delays [steps] for uniforms ``u``."""
        if self.law == 'fixed':
            return np.full(u.shape, self.low, dtype=np.int64)
        if self.law == 'uniform':
            return self.low + np.floor(u * (self.high - self.low + 1)).astype(np.int64)
        with np.errstate(divide='ignore'):
            d = np.floor(np.log1p(-u) / np.log1p(-self.p)) if self.p < 1.0 else np.zeros(u.shape)
        return np.minimum(d, self.high).astype(np.int64)


@dataclass(frozen=True)
class Loss:
    """Which messages are lost.

    :ivar model: ``bernoulli`` (each message independently with ``p``) or ``gilbert_elliott``
        (a two-state Markov chain per directed link, advanced at each message: good -> bad
        with ``p_good_bad``, bad -> good with ``p_bad_good``; a message is lost with
        ``loss_good`` or ``loss_bad`` in the state the chain is in).
    """

    model: str = 'bernoulli'
    p: float = 0.0
    p_good_bad: float = 0.0
    p_bad_good: float = 1.0
    loss_good: float = 0.0
    loss_bad: float = 1.0

    @property
    def active(self) -> bool:
        """Return whether any message can be lost."""
        if self.model == 'bernoulli':
            return self.p > 0.0
        return self.loss_good > 0.0 or (self.p_good_bad > 0.0 and self.loss_bad > 0.0)

    @property
    def bad_fraction(self) -> float:
        """Return the stationary probability of the bad state."""
        total = self.p_good_bad + self.p_bad_good
        return self.p_good_bad / total if total > 0.0 else 0.0


@dataclass(frozen=True)
class Channel:
    """What one kind of link does to its messages (the agents' links or the leader's)."""

    delay: Delay = Delay()
    loss: Loss = Loss()
    noise_position: float = 0.0
    noise_velocity: float = 0.0
    period: int = 1

    @property
    def active(self) -> bool:
        """Return whether the channel changes anything against exact, current states."""
        return (self.delay.high > 0 or self.loss.active or self.noise_position > 0.0
                or self.noise_velocity > 0.0 or self.period > 1)

    @property
    def oldest(self) -> int:
        """Return the oldest age [steps] a message can have without a loss."""
        return self.delay.high + self.period - 1


@dataclass(frozen=True)
class NetworkSpec:
    """The scenario's ``network:`` section, in steps (see ``docs/network.md``).

    :ivar agents: the channel of the agents' links.
    :ivar leader: the channel of the leader's state to the informed agents.
    :ivar model: ``communication`` (own state current) or ``input`` (own state delayed too).
    :ivar max_age: information older than this [steps] is dropped.
    :ivar compensation: ``none`` or ``predict`` (each state used extrapolated by its age).
    :ivar dt: the step [s] the ages are counted in (the prediction's unit of time).
    """

    agents: Channel = Channel()
    leader: Channel = Channel()
    model: str = 'communication'
    max_age: int = 0
    compensation: str = 'none'
    dt: float = 0.0

    @property
    def predict(self) -> bool:
        """Return whether the states used are extrapolated to the current step."""
        return self.compensation == 'predict'

    @property
    def active(self) -> bool:
        """Return whether a run differs from one without the section."""
        return self.agents.active or self.leader.active


def steps_of(value, key: str, dt: float) -> int:
    """Return a time [s] as a whole number of steps; refuse one that is not.

    The rule: ``x`` is ``round(x / dt)`` steps when ``|x / dt - round(x / dt)| <= 1e-9``.

    :param value: the time from the scenario, ``>= 0``.
    :param key: its dotted key.
    :param dt: the step.
    :return: the steps.
    :raises ScenarioError: for a negative time or one between two steps.
    """
    x = number(value, key)
    if x < 0.0:
        raise ScenarioError(key, f'must be >= 0 s, got {value!r}')
    steps = round(x / dt)
    if abs(x / dt - steps) > STEP_TOLERANCE:
        raise ScenarioError(key, f'must be a whole number of steps (dt = {dt:g} s), got '
                            f'{value!r} = {x / dt:.6g} steps')
    if steps > MAX_WINDOW:
        raise ScenarioError(key, f'must be <= {MAX_WINDOW} steps, got {steps}')
    return int(steps)


def _probability(value, key: str) -> float:
    x = number(value, key)
    if not 0.0 <= x <= 1.0:
        raise ScenarioError(key, f'must be in [0, 1], got {value!r}')
    return x


def _parse_delay(value, key: str, dt: float) -> Delay:
    if not isinstance(value, dict):
        steps = steps_of(0 if value is None else value, key, dt)
        return Delay('fixed', steps, steps)
    law = choice(value.get('law', 'fixed'), f'{key}.law', DELAY_LAWS)
    if law == 'fixed':
        only(value, ('law', 'value'), f'{key}.')
        steps = steps_of(value.get('value', 0), f'{key}.value', dt)
        return Delay('fixed', steps, steps)
    if law == 'uniform':
        only(value, ('law', 'min', 'max'), f'{key}.')
        if 'max' not in value:
            raise ScenarioError(f'{key}.max', 'missing (the largest delay [s])')
        low = steps_of(value.get('min', 0), f'{key}.min', dt)
        high = steps_of(value['max'], f'{key}.max', dt)
        if high < low:
            raise ScenarioError(f'{key}.max', f'must be >= min ({low * dt:g} s), got '
                                f'{value["max"]!r}')
        return Delay('uniform', low, high)
    only(value, ('law', 'mean', 'max'), f'{key}.')
    for name in ('mean', 'max'):
        if name not in value:
            raise ScenarioError(f'{key}.{name}', 'missing (geometric delay: mean and max [s])')
    mean = number(value['mean'], f'{key}.mean')
    if mean < 0.0:
        raise ScenarioError(f'{key}.mean', f'must be >= 0 s, got {value["mean"]!r}')
    high = steps_of(value['max'], f'{key}.max', dt)
    return Delay('geometric', 0, high, 1.0 / (1.0 + mean / dt))


def _parse_loss(value, key: str) -> Loss:
    if not isinstance(value, dict):
        return Loss('bernoulli', _probability(0 if value is None else value, key))
    model = choice(value.get('model', 'bernoulli'), f'{key}.model', LOSS_MODELS)
    if model == 'bernoulli':
        only(value, ('model', 'p'), f'{key}.')
        return Loss('bernoulli', _probability(value.get('p', 0), f'{key}.p'))
    names = ('p_good_bad', 'p_bad_good', 'loss_good', 'loss_bad')
    only(value, ('model', *names), f'{key}.')
    for name in ('p_good_bad', 'p_bad_good'):
        if name not in value:
            raise ScenarioError(f'{key}.{name}', 'missing (a transition probability of the '
                                'Gilbert-Elliott channel)')
    probs = {name: _probability(value.get(name, default), f'{key}.{name}')
             for name, default in zip(names, (0, 0, 0, 1))}
    return Loss('gilbert_elliott', **probs)


def _parse_channel(section: dict, prefix: str, dt: float) -> Channel:
    noise = mapping(section.get('noise'), f'{prefix}noise')
    only(noise, ('position', 'velocity'), f'{prefix}noise.')
    stds = []
    for name in ('position', 'velocity'):
        std = number(noise.get(name, 0), f'{prefix}noise.{name}')
        if std < 0.0:
            raise ScenarioError(f'{prefix}noise.{name}', f'must be >= 0, got {std!r}')
        stds.append(std)
    period = integer(section.get('period', 1), f'{prefix}period')
    if not 1 <= period <= MAX_WINDOW:
        raise ScenarioError(f'{prefix}period', f'must be in [1, {MAX_WINDOW}] steps, got '
                            f'{period}')
    return Channel(_parse_delay(section.get('delay'), f'{prefix}delay', dt),
                   _parse_loss(section.get('loss'), f'{prefix}loss'), stds[0], stds[1], period)


def parse_network(value, dt: float) -> NetworkSpec:
    """Validate the scenario's ``network:`` section; return it in steps.

    :param value: the section (``None``: absent).
    :param dt: the step [s].
    :return: the spec (inactive when absent or all zero).
    :raises ScenarioError: naming the first invalid key.
    """
    section = mapping(value, 'network')
    only(section, NETWORK_KEYS, 'network.')
    agents = _parse_channel(section, 'network.', dt)
    leader_section = mapping(section.get('leader'), 'network.leader')
    only(leader_section, CHANNEL_KEYS, 'network.leader.')
    leader = _parse_channel(leader_section, 'network.leader.', dt)
    model = choice(section.get('model', 'communication'), 'network.model', DELAY_MODELS)
    compensation = choice(section.get('compensation', 'none'), 'network.compensation',
                          COMPENSATIONS)
    oldest = max(agents.oldest, leader.oldest)
    if 'max_age' in section:
        max_age = steps_of(section['max_age'], 'network.max_age', dt)
        if max_age < oldest:
            raise ScenarioError('network.max_age', f'must be >= the largest delay plus the '
                                f'period less one step ({oldest} steps = {oldest * dt:g} s), '
                                f'or no message is ever used, got {section["max_age"]!r}')
    else:
        # A held state survives one lost refresh and is dropped at the second.
        max_age = oldest + max(agents.period, leader.period)
    if max_age > MAX_WINDOW:
        raise ScenarioError('network.max_age', f'must be <= {MAX_WINDOW} steps, got '
                            f'{max_age}')
    return NetworkSpec(agents, leader, model, max_age, compensation, float(dt))
