"""What `identify` and the command line share with jaxunilat, beyond its public API.

Argument validation with messages that name the parameter, the value and the valid
range; the output-path checks every command runs before any work, and the writer that
never leaves a partial file; the command line's
error types and exit codes. `identify` imports only
jaxunilat's public API and this module (a test checks it), so the two packages depend
one way.

No stability promise: these names serve the project's own packages and may change
between releases.
"""

from ._errors import EXIT_OK as EXIT_OK, PROG as PROG, RunError as RunError, UsageError as UsageError
from ._executables import kept_call as kept_call
from ._io import (
    check_output_dir as check_output_dir,
    check_output_paths as check_output_paths,
    special_kind as special_kind,
    write_atomically as write_atomically,
)
from ._validate import (
    check_choice as check_choice,
    check_finite as check_finite,
    check_range as check_range,
)
