"""identify's `jaxunilat` commands: `identify`, `import`, `qualify` and `export`.

Each module holds one command and its `register(commands)`, named in jaxunilat's command
table (`jaxunilat._cli._main.COMMANDS`; what a command's module provides:
`jaxunilat._internal._cli`). They use identify's public names and `jaxunilat._internal`
only; heavy imports stay inside the handlers.
"""
