"""The command line's error types and exit codes, shared by every subcommand.

The command line maps exceptions to exit codes by type, never by message:

- `UsageError` (the arguments, e.g. two flags that exclude each other) and `InputError`
  (a value or file the user gave, found invalid at the public boundary): exit 2.
- `RunError` (a run-time failure: the solver diverged, a file could not be written): exit 1.
- A command's own result, e.g. a fit that did not converge: the code its handler returns
  (`EXIT_NOT_CONVERGED`).
- Anything else is a bug: exit `EXIT_INTERNAL` with one line naming the exception's type
  (`--debug` prints the traceback). A plain `ValueError` raised deep inside a computation
  is such a bug, never "bad input".
"""

#: The command's name, as its messages spell it.
PROG = "jaxunilat"
#: Exit codes: success, a run-time failure, bad usage or input.
EXIT_OK, EXIT_RUNTIME, EXIT_USAGE = 0, 1, 2
#: Exit code of an internal error (a bug), as Python's own for an uncaught exception.
EXIT_INTERNAL = 1
#: Exit code of a command whose standard output's reader went away (`| head`): 128 +
#: SIGPIPE, as a Unix tool that the signal ended; nothing is printed.
EXIT_BROKEN_PIPE = 141
#: Exit code of a fit that did not converge or an import refused as implausible (its
#: report is still printed).
EXIT_NOT_CONVERGED = 3


class UsageError(Exception):
    """Bad usage of the command line (flags that exclude each other, a missing argument):
    reported as one line, exit code 2."""


class InputError(ValueError):
    """A value the user gave (a parameter, a file's content) is invalid: the message names
    the parameter, the value and the valid range. A `ValueError`, so code that catches bad
    input as `ValueError` keeps working; the command line reports it as one line, exit 2,
    while a plain `ValueError` from deep inside a computation is an internal error."""


class RunError(Exception):
    """A run-time failure: reported as one line, exit code 1."""
