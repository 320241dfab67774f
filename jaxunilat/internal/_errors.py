"""The command line's error types and exit codes, shared by every subcommand."""

#: The command's name, as its messages spell it.
PROG = "jaxunilat"
#: Exit codes: success, a run-time failure, bad usage.
EXIT_OK, EXIT_RUNTIME, EXIT_USAGE = 0, 1, 2


class UsageError(Exception):
    """Bad user input: reported as one line, exit code 2."""


class RunError(Exception):
    """A run-time failure: reported as one line, exit code 1."""
