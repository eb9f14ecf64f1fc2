"""The one exception type a user sees as a one-line message."""


class SonarRasterError(ValueError):
    """Bad input or an environment problem, with a message a user can act on.

    The CLI prints ``str(error)`` on one line and exits with status 2.
    """
