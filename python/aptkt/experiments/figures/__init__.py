"""The paper's experiments (§5.3–5.6), one module per figure.

Each module has ``NAME``, ``TITLE``, ``plan(ctx)`` (the prior knowledge and runs it needs) and
``analyse(ctx, rows)`` (plots, tables and its report section from the runs' result rows).
"""

from aptkt.experiments.figures import fig6, fig7, fig8, fig9, fig10, fig11

FIGURES = {m.NAME: m for m in (fig6, fig7, fig8, fig9, fig10, fig11)}

__all__ = ["FIGURES"]
