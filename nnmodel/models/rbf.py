"""``rbf``: Gaussian radial-basis network on tapped delays.

    y[k] = a.z + c + sum_j w_j exp(-|z - c_j|^2 / (2 s_j^2)),  z = (y[k-1..k-na], u[k-d..], rh[k])

Training without gradients (seconds): centres c_j by k-means (scikit-learn) on the
normalised one-step regressors, widths s_j = ``width_factor`` x the mean distance from c_j
to its ``width_neighbours`` nearest centres, then the output layer (w, a, c) by ridge
regression on one-step targets.  Optional gradient fine-tuning of everything (centres,
widths, weights) with the shared Lightning loop: ``max_epochs > 0``, one step ahead
(``horizon = 1``) or in closed loop (``horizon > 1``, training settings).  With ``na = 0`` it is an NFIR
network; ``memory_filters`` add long input memory (see :mod:`nnmodel.models.features`).
"""
from __future__ import annotations

import numpy as np
import torch

from .base import NeuralModel
from .ff import LAG_CHECKS
from .lag import LagSimulator, RBFMap, _normal_equations, ridge
from .params import MAX_CENTRES, flag, pos_float, pos_int, size


class RBFModel(NeuralModel):
    """Gaussian RBF network: k-means centres, spacing-based widths, ridge output layer."""

    kind = "rbf"
    IN_DEFAULT_SET = True
    DEFAULTS = {"max_epochs": 0, "grad_clip": 1.0}
    CHECKS = {"na": LAG_CHECKS["na"], "nb": LAG_CHECKS["nb"], "feedthrough": flag,
              "n_centres": size(MAX_CENTRES),
              "width_factor": pos_float,
              "width_neighbours": size(MAX_CENTRES),
              "alpha": lambda v: pos_float(v, zero=True),
              "kmeans_samples": size(10_000_000)}
    CHECK_PARAMS = {"n_centres": 6}

    def __init__(self, na: int = 2, nb: int = 20, n_centres: int = 100, width_factor: float = 1.0,
                 width_neighbours: int = 2, alpha: float = 1e-6, kmeans_samples: int = 20000,
                 feedthrough: bool = True, **settings):
        self._set_params_from(locals())

    def _build_core(self, features):
        n_tap = 1 + features.n_ref      # the voltage, and the linear start's output (a residual core)
        fmap = RBFMap(self.na, n_tap * self.nb + features.n_mem + features.n_rh, self.n_centres,
                      n_sched=features.n_sched)
        return LagSimulator(self.na, self.nb, features.n_rh, fmap, self.feedthrough, n_mem=features.n_mem,
                            n_tap=n_tap, residual=features.n_ref > 0)

    def _initialise(self, core, train):
        from sklearn.cluster import KMeans

        Z, t = core.regressors(train)
        rng = np.random.default_rng(self.seed)
        sub = Z if len(Z) <= self.kmeans_samples else Z[rng.choice(len(Z), self.kmeans_samples, replace=False)]
        M = min(self.n_centres, len(np.unique(sub, axis=0)))
        km = KMeans(n_clusters=M, n_init=1, random_state=self.seed).fit(sub)
        C = km.cluster_centers_
        if M < self.n_centres:  # fewer distinct points than centres: duplicate (weights share)
            C = np.concatenate([C, C[rng.integers(0, M, self.n_centres - M)]])
        D = np.sqrt(((C[:, None, :] - C[None, :, :]) ** 2).sum(-1))
        np.fill_diagonal(D, np.inf)
        p = min(self.width_neighbours, len(C) - 1) if len(C) > 1 else 0
        if p:
            spacing = np.sort(D, 1)[:, :p].mean(1)
            spacing[~np.isfinite(spacing) | (spacing <= 0)] = 1.0
        else:
            spacing = np.ones(len(C))
        width = self.width_factor * spacing
        fmap = core.fmap
        with torch.no_grad():
            fmap.centres.copy_(torch.as_tensor(C, dtype=torch.float32))
            fmap.log_width.copy_(torch.as_tensor(np.log(width), dtype=torch.float32))
            Phi = fmap.features(torch.as_tensor(Z, dtype=torch.float32)).double().numpy()
        K = fmap.n_sched
        if not K:
            X = np.concatenate([Z, Phi], 1)
            w = ridge(X, t, self.alpha, penalise_from=Z.shape[1])
            d = Z.shape[1]
            with torch.no_grad():
                fmap.lin.copy_(torch.as_tensor(w[:d], dtype=torch.float32))
                fmap.weight.copy_(torch.as_tensor(w[d:-1], dtype=torch.float32))
                fmap.bias.fill_(float(w[-1]))
            resid = t - np.concatenate([X, np.ones((len(X), 1))], 1) @ w
        else:  # RH-scheduled bypass: [z' (x) s, s, Gaussians] in one ridge regression
            S, Zl = Z[:, -K:], Z[:, :-K]
            m = Zl.shape[1]

            def blocks(sl):
                return np.concatenate([(Zl[sl, :, None] * S[sl, None, :]).reshape(-1, m * K), S[sl], Phi[sl]], 1)
            G, rhs = _normal_equations(blocks, t)
            reg = np.zeros(len(G))
            reg[m * K + K:] = self.alpha * len(t)          # Gaussian weights penalised
            reg[:m * K] = 1e-8 * len(t)                     # bypass: a whisper of ridge
            G[np.diag_indices_from(G)] += reg + 1e-10 * np.trace(G) / len(G)
            w = np.linalg.solve(G, rhs)
            W = w[:m * K].reshape(m, K).T
            with torch.no_grad():
                fmap.lin.copy_(torch.as_tensor(W, dtype=torch.float32))
                fmap.bias.copy_(torch.as_tensor(w[m * K:m * K + K], dtype=torch.float32))
                fmap.weight.copy_(torch.as_tensor(w[m * K + K:], dtype=torch.float32))
            resid = t - np.einsum("nm,nk,km->n", Zl, S, W) - S @ w[m * K:m * K + K] - Phi @ w[m * K + K:]
        self.init_report_ = {"one_step_rmse": float(np.sqrt(np.mean(resid ** 2))),
                             "mean_width": float(width.mean())}
