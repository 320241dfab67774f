"""What `jaxunilat.identify` and the command line share with jaxunilat's engine, beyond
its public API: private to the project.

Argument validation with messages that name the parameter, the value and the valid
range; the output-path checks every command runs before any work, and the writer that
never leaves a partial file; how a message shows a user's paths and values (`_text.py`:
control characters escaped, numbers in bounded width); the command line's
error types and exit codes, and what a command's module provides (`_cli.py`); where latency-bound work runs on a
machine whose default backend is an accelerator (`_placement.py`: the host CPU). `jaxunilat.identify`
imports only jaxunilat's public API and this module (a test checks it), so identify
depends on the engine and never the other way.

No stability promise: these names serve the project's own packages and may change
between releases.

Each name is imported from its module when first used, so that the command line's light
paths (`jaxunilat --help`) import neither JAX nor NumPy through this package.
"""

from ._lazy import lazy_names

#: Each name, and the module of this package that defines it.
_WHERE = {
    "check_plot_format": "._cli",
    "input_errors": "._cli",
    "output_errors": "._cli",
    "EXIT_BROKEN_PIPE": "._errors",
    "EXIT_INTERNAL": "._errors",
    "EXIT_NOT_CONVERGED": "._errors",
    "EXIT_OK": "._errors",
    "EXIT_RUNTIME": "._errors",
    "EXIT_USAGE": "._errors",
    "PROG": "._errors",
    "InputError": "._errors",
    "RunError": "._errors",
    "UsageError": "._errors",
    "kept_call": "._executables",
    "bundled_data": "._io",
    "check_output_dir": "._io",
    "check_output_paths": "._io",
    "mode_kind": "._io",
    "special_kind": "._io",
    "write_atomically": "._io",
    "host_device": "._placement",
    "keep_placement": "._placement",
    "latency_bound": "._placement",
    "on_host": "._placement",
    "bounded_numbers": "._text",
    "finite_or_none": "._text",
    "number": "._text",
    "printable": "._text",
    "shown": "._text",
    "check_choice": "._validate",
    "check_finite": "._validate",
    "check_range": "._validate",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = lazy_names(__name__, _WHERE)
