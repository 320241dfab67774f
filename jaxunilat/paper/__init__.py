"""The paper's figures and claims, reproduced: `reproduce(out)` writes every figure of
Kukla, Posiadała, Skalmierski & Tylikowski (1990) and a report of which of its claims
the runs support (`jaxunilat reproduce` on the command line)."""

from ._reproduce import Claim as Claim, Report as Report, coupling_run as coupling_run, reproduce as reproduce
