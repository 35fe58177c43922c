"""What one invocation of the reproduction runs: full or ``--quick``, and the grid of the
sweep of Su, Wang, Lin 2009 Fig. 3 (the one experiment that runs a sweep beside its preset)."""

from dataclasses import dataclass

#: The group sizes of Su 2009 Fig. 3.
FIG3_SIZES = (100, 300, 500, 1000)

#: Informed fractions delta of our Fig. 3 sweep (the paper does not list its grid; 0.1 and
#: 0.27 are the two values its text quotes; 0.65 splits the gap where eta crosses 0.8).
FIG3_FRACTIONS = (0.05, 0.1, 0.15, 0.2, 0.27, 0.35, 0.5, 0.65, 0.75, 1.0)

#: --quick: a sweep small enough for a unit test.
QUICK_FIG3_SIZES = (20, 40)
QUICK_FIG3_FRACTIONS = (0.1, 0.5)
QUICK_FIG3_DURATION = 2.0


@dataclass
class Plan:
    """What a reproduction runs.

    :ivar quick: tiny durations and sizes (for tests).
    :ivar realisations: realisations per point of Fig. 3.
    :ivar sizes: group sizes N of Fig. 3.
    :ivar fractions: informed fractions delta of Fig. 3.
    :ivar fig3_overrides: further ``--set`` overrides of every Fig. 3 run.
    """

    quick: bool
    realisations: int
    sizes: tuple[int, ...] = FIG3_SIZES
    fractions: tuple[float, ...] = FIG3_FRACTIONS
    fig3_overrides: tuple[str, ...] = ()

    @classmethod
    def make(cls, quick: bool, realisations: int | None) -> 'Plan':
        """Return the full plan or the ``--quick`` one."""
        if quick:
            return cls(True, realisations or 1, QUICK_FIG3_SIZES, QUICK_FIG3_FRACTIONS,
                       (f'duration={QUICK_FIG3_DURATION:g}',))
        return cls(False, realisations or 10)
