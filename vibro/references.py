"""The paper this project starts from, cited the same way everywhere (help texts, captions, sidecars).

No imports: the command line reads it while building its help.

Examples
--------
>>> PAPER_TITLE
'A new type of bilateral vibro-impact model: random vibration analysis'
"""

PAPER_TITLE = "A new type of bilateral vibro-impact model: random vibration analysis"

PAPER = (f'"{PAPER_TITLE}": stochastic averaging of the energy envelope for a Duffing-type oscillator between two '
         "rigid barriers, with Ma's velocity-dependent restitution coefficient")
"""The full citation as far as our copy of the paper gives it (title and content; see docs/paper-readings.md)."""

READINGS = "docs/paper-readings.md"
"""Where the repository states how it reads the paper's typos and ambiguities."""
