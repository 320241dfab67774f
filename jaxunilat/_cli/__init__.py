"""The `jaxunilat` command line: every subcommand, including `identify`, `import`,
`qualify` and `export` (which call the `identify` package's public API).

Subcommands live in their own modules and are imported only when used, so that
`jaxunilat --help` stays fast.
"""

from ._main import main as main
