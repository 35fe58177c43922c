"""Errors raised by the core for invalid input."""

#: Longest text :func:`one_line` returns: an error quotes the user's value, which may be huge
#: (a value of megabytes derived by a sweep, a list of a million numbers); the start of it is
#: enough to recognise it.
MAX_LINE = 400


def one_line(text: str, limit: int = MAX_LINE) -> str:
    """Return ``text`` with unprintable characters escaped, cut to at most ``limit`` characters.

    Keys come from the user's file (an unknown key may hold any character), and the error is
    reported as exactly one line of a readable length: a longer text keeps its start and
    says how much was cut.

    :param text: the text.
    :param limit: the longest text returned (at least 60).
    """
    # Escaping only the start keeps the cost bounded by `limit`, not by the text's length.
    head = text[:limit]
    if not head.isprintable():
        head = ''.join(c if c.isprintable() else c.encode('unicode_escape').decode('ascii')
                       for c in head)
    if len(text) <= limit and len(head) <= limit:
        return head
    return f'{head[:limit - 45]} ... (cut: {len(text)} characters in all)'


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
