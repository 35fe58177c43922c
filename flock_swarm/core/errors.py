"""Errors raised by the core for invalid input."""


def one_line(text: str) -> str:
    """Return ``text`` with line breaks and other unprintable characters escaped.

    Keys come from the user's file (an unknown key may hold any character), and the error is
    reported as exactly one line.
    """
    if text.isprintable():
        return text
    return ''.join(c if c.isprintable() else c.encode('unicode_escape').decode('ascii')
                   for c in text)


class ScenarioError(ValueError):
    """An invalid scenario value; ``key`` names it with its dotted path."""

    def __init__(self, key: str, reason: str) -> None:
        """Create the error; the message is one line whatever the key and reason hold.

        :param key: dotted path of the offending key, e.g. ``interaction.r``.
        :param reason: what is wrong, one line.
        """
        key, reason = one_line(str(key)), one_line(reason)
        super().__init__(f'{key}: {reason}')
        self.key = key
        self.reason = reason


class PluginError(ScenarioError):
    """A registered law or leader model that cannot be used; names its entry point or law.

    Raised when a plugin cannot be loaded (:mod:`flock_swarm.core.registry`), when a law's
    claims fail their check (``antisymmetric``), and when a law's output has the wrong shape
    at any step (:mod:`flock_swarm.core.laws.base`).
    """
