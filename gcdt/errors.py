"""The one exception type for bad user input.

Library code raises `GcdtError` with a one-line message that names the problem and the fix;
the CLI prints it as `gcdt: error: ...` and exits with status 2. Anything else is a bug and
keeps its traceback.
"""


class GcdtError(ValueError):
    """Bad input from a user: wrong name, out-of-range number, missing file."""
