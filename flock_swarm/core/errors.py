"""Errors raised by the core for invalid input."""


class ScenarioError(ValueError):
    """An invalid scenario value; ``key`` names it with its dotted path."""

    def __init__(self, key: str, reason: str) -> None:
        """Create the error.

        :param key: dotted path of the offending key, e.g. ``interaction.r``.
        :param reason: what is wrong, one line.
        """
        super().__init__(f'{key}: {reason}')
        self.key = key
        self.reason = reason
