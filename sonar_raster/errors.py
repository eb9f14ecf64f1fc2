"""The one exception type a user sees as a one-line message."""


class SonarRasterError(ValueError):
    """Bad input or an environment problem, with a message a user can act on.

    The CLI prints ``str(error)`` on one line and exits with status 2.
    """


class SonarRasterTypeError(SonarRasterError, TypeError):
    """An argument of the wrong type: a :class:`SonarRasterError` that is also a ``TypeError``."""


class InputWarning(UserWarning):
    """Input that was read with a repair, or settings that look wrong but can still run.

    The CLI prints ``sonar-raster: warning: <message>`` and carries on (other warnings stop a
    command as errors). Each message names what was found and what to do about it.
    """


class DeprecatedOptionWarning(InputWarning, FutureWarning):
    """A command-line option or file key that still works under an old name."""
