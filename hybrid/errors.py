"""Exceptions raised by the framework.

Every error says what is wrong and how to fix it. They all derive from :class:`VibroError`, which is a
``ValueError``, so ``except ValueError`` keeps working for callers that do not know this package.
"""


class VibroError(ValueError):
    """Base class of every error raised on bad input or an impossible request."""


class ModelError(VibroError):
    """A model or automaton declaration is inconsistent (unknown symbols, bad reset, non-confining potential)."""


class ParameterError(VibroError):
    """A parameter value is out of its admissible range (negative barrier distance, noise intensity, step)."""


class RestitutionError(VibroError):
    """A restitution law gives a coefficient outside (0, 1]."""


class NormalisationError(VibroError):
    """A density cannot be normalised (no confinement, or energy grows without bound)."""


class StepSizeError(VibroError):
    """A time step is so large that a path could jump across the gap between the barriers."""


class VibroWarning(UserWarning):
    """Base class of the warnings of this package: the result is computed but needs the user's attention."""


class TruncationWarning(VibroWarning):
    """A result is computed on a truncated range that cuts off a noticeable part of the probability mass."""


class DensityResolutionWarning(VibroWarning):
    """A density is written on a grid or histogram that cannot hold it: its mass sits in a few cells, or it does not
    integrate to its mass on its own grid (see :mod:`hybrid.resolution`)."""


class CheckpointError(ParameterError):
    """A checkpoint cannot be used: unreadable, edited (checksum), or written by another run (fingerprint)."""


class HistogramRangeWarning(VibroWarning):
    """More than a small share of the samples fell outside a histogram's range (they are counted, not binned)."""


class OutputError(ParameterError):
    """An output cannot be written: a missing or read-only folder, a name too long, a directory or special file in
    the way, two outputs on one file, or a full disk. Raised before the work starts wherever it can be foreseen."""


class CudaUnavailableError(VibroError):
    """``scheduler='cuda'`` was asked for, but numba-cuda is not installed or no CUDA device was found."""
