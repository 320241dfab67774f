"""Figures of runs: the ball's trajectory, the coupling's gap and impact forces.

matplotlib is imported only when a figure is drawn, never on `import jaxunilat`.
"""

from ._ball import plot_ball as plot_ball, save_figure as save_figure
from ._coupling import plot_coupling as plot_coupling, plot_impact_forces as plot_impact_forces
