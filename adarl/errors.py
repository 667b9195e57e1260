"""The one exception type for bad user input.

Anything a user can get wrong (a flag, a config field, a task name, a run folder) raises
`UsageError` with a one-line message that names the bad value and what is allowed. The CLI turns
it into `adarl: error: <message>` on stderr and exit code 2.
"""


class UsageError(ValueError):
    """Bad user input; the message is a single line naming the value and what is allowed."""


def check_choice(kind: str, value: str, allowed) -> str:
    """Return `value` if it is one of `allowed`, else raise a one-line `UsageError`."""
    allowed = list(allowed)
    if value not in allowed:
        raise UsageError(f"unknown {kind} {value!r}; allowed: {', '.join(map(str, allowed))}")
    return value
