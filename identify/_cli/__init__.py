"""identify's `jaxunilat` commands: `identify`, `import`, `qualify` and `export`.

Each module holds one command and its `register(commands)`, which `jaxunilat` finds
through the `jaxunilat.commands` entry points (pyproject.toml; the protocol:
`jaxunilat.internal._cli`). They use identify's public names and `jaxunilat.internal`
only; heavy imports stay inside the handlers.
"""
