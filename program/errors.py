"""Errors caused by user input (a bus string, a config value, a CLI argument).

The CLI turns every `UserInputError` into one line on stderr and exit code 2; its message
must name the culprit and, where it helps, the accepted forms.
"""


class UserInputError(ValueError):
    """A value supplied by the user is wrong; the message says which and why."""
