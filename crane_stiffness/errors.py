"""Base exception of the crane_stiffness package.

Each subpackage has its own ``errors`` module whose exceptions derive from :class:`CraneStiffnessError`, so a caller
can catch everything this package raises with one ``except``.
"""


class CraneStiffnessError(Exception):
    """Base class of every error raised on purpose by crane_stiffness."""
