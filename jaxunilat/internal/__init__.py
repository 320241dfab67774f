"""What `identify` and the command line share with jaxunilat, beyond its public API.

Argument validation with messages that name the parameter, the value and the valid
range; the output-path checks every command runs before any work, and the writer that
never leaves a partial file; how a message shows a user's paths and values (`_text.py`:
control characters escaped, numbers in bounded width); the command line's
error types and exit codes, and how a package registers a `jaxunilat` command
(`_cli.py`: the `jaxunilat.commands` entry points); where latency-bound work runs on a
machine whose default backend is an accelerator (`_placement.py`: the host CPU). `identify` imports only
jaxunilat's public API and this module (a test checks it), so the two packages depend
one way.

No stability promise: these names serve the project's own packages and may change
between releases.
"""

from ._cli import (
    COMMANDS_GROUP as COMMANDS_GROUP,
    check_plot_format as check_plot_format,
    input_errors as input_errors,
    output_errors as output_errors,
)
from ._errors import (
    EXIT_BROKEN_PIPE as EXIT_BROKEN_PIPE,
    EXIT_INTERNAL as EXIT_INTERNAL,
    EXIT_NOT_CONVERGED as EXIT_NOT_CONVERGED,
    EXIT_OK as EXIT_OK,
    EXIT_RUNTIME as EXIT_RUNTIME,
    EXIT_USAGE as EXIT_USAGE,
    PROG as PROG,
    InputError as InputError,
    RunError as RunError,
    UsageError as UsageError,
)
from ._executables import kept_call as kept_call
from ._io import (
    bundled_data as bundled_data,
    check_output_dir as check_output_dir,
    check_output_paths as check_output_paths,
    mode_kind as mode_kind,
    special_kind as special_kind,
    write_atomically as write_atomically,
)
from ._placement import (
    host_device as host_device,
    keep_placement as keep_placement,
    latency_bound as latency_bound,
    on_host as on_host,
)
from ._text import (
    bounded_numbers as bounded_numbers,
    number as number,
    printable as printable,
    shown as shown,
)
from ._validate import (
    check_choice as check_choice,
    check_finite as check_finite,
    check_range as check_range,
)
