"""The `jaxunilat` command line.

`_main` is the shell: it builds the parser, dispatches to the command and maps the
exception that ends a command to its exit code and one line (`--debug`: the traceback of
an internal error). Each of jaxunilat's commands lives in its own module, imported only
when the parser is built (`jaxunilat --help` stays fast, heavy imports sit inside the
handlers): `_simulate` (`simulate ball|coupling`), `_sensitivity`, `_reproduce`,
`_bench`; `_args` holds the argument helpers they share.

Other packages add commands through the `jaxunilat.commands` entry points (protocol:
`jaxunilat._internal._cli`): `identify`, `import`, `qualify` and `export` are
`identify._cli`'s. jaxunilat never imports identify; without it installed, those
commands are absent.
"""

from ._main import main as main
