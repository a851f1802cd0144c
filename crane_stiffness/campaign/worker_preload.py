"""Imported once by the fork server of the analysis worker processes (crane_stiffness.campaign.parallel): does what
every session's analysis pays for on first use — loading the model's compiled kernels (a rest pose, a batch solve,
the exact tangent) and drawing and saving a figure with matplotlib's Agg backend — so that each worker forked from
the server starts warm instead of paying it again. Importing it has that effect on purpose; nothing else imports it.
"""
from __future__ import annotations

import io

import matplotlib
import numpy as np

matplotlib.use('Agg')  # headless, as the analysis figures
import matplotlib.pyplot as plt  # noqa: E402

from crane_stiffness.model import lab_model, rest_pose, solve_batch, tangent_stiffness  # noqa: E402


def warm() -> None:
    g = lab_model(0.5, 50.0)
    tangent_stiffness(g, rest_pose(g))
    solve_batch(g, np.array([[0.0, 1.0, 0.0, 0.0, 0.0, 0.0]]))
    fig, ax = plt.subplots()
    ax.plot([0.0, 1.0], [0.0, 1.0], label='warm')
    ax.legend()
    fig.savefig(io.BytesIO(), format='png')
    plt.close(fig)


warm()
