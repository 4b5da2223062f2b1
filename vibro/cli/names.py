"""Registry names the parsers show, kept here so that ``vibro --help`` imports neither sympy nor numba.

``tests/test_architecture.py`` checks that each tuple equals its registry, so they cannot drift apart.
"""

SCHEMES = ("em", "milstein", "naive", "splitting")
"""Names of ``hybrid.stochastic.SCHEMES``."""
AUTOMATON_ONLY_SCHEMES = ("baoab", "symplectic")
"""Names of ``hybrid.stochastic.AUTOMATON_SCHEMES`` that are not oscillator scheme names (the front end runs them
for ``milstein`` and ``splitting``)."""
DENSITY_METHODS = ("chain", "exact-two-impact", "jump", "paper")
"""Names of ``averaging.METHODS``."""
MODELS = ("duffing", "duffing-forced", "duffing-vdp", "rayleigh")
"""Names of ``models.MODELS``."""
SOLVE_METHODS = ("auto", "exact", "paper", "jump", "chain", "fpk", "monte-carlo")
"""``vibro.solve.solver.METHODS``, in its order (cheapest first)."""
