"""G by BIC: ``n_components="bic"`` of ``fit``, the studies and the method-level splits (the default is ``"cv"``,
:mod:`workbench.models.autoconfig`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from workbench.errors import ModelError
from workbench.models.proposed import HumanBehaviorModel

__all__ = ["select_components"]


def select_components(
    train: Any, plant: Any, candidates: Sequence[int] = range(2, 9), seed: int = 0
) -> int:
    """G by BIC (TP-GMM parameter count) of the proposed model's variability fit: ``n_components="bic"`` (on a
    :class:`~workbench.data.demonstrations.DemonstrationSet`).

    Each candidate model scores its own training data through :meth:`HumanBehaviorModel.bic`, i.e. with the
    residuals, frames and standardization it was fitted with (one path for fitting and scoring).
    """
    best: tuple[float, int] | None = None
    for G in candidates:
        if G * 20 > train.n_samples:  # far fewer samples than parameters: BIC is meaningless there
            break
        m = HumanBehaviorModel(
            plant, n_components=int(G), random_state=seed, fit_objective=False, noise_folds=0
        ).fit(train)
        bic = m.bic(train)
        if best is None or bic < best[0]:
            best = (bic, int(G))
    if best is None:
        raise ModelError(f"too few samples ({train.n_samples}) to choose the number of components")
    return best[1]
