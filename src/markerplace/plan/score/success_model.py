"""Probability that a camera pose localizes, as a logistic function of its localizability score.

The localizability score ``s = -H(Lambda)`` (nats, :func:`markerplace.plan.score.localizability.score`)
ranks poses, but a placement objective that counts *poses that localize* needs a calibrated
probability. :class:`SuccessModel` is that link::

    P(success | s) = sigmoid(intercept + slope * s),     slope >= 0 (per nat)

fitted by :func:`fit_success_model` on pairs (score of a map image's pose, whether that image
localized). Where the pairs come from is the caller's business; this module only fits,
evaluates and serializes the model, plus two diagnostics: :func:`roc_auc` (how well the score
separates successes from failures) and :func:`calibration_curve` (observed success rate per
score bin, to compare with the fitted curve).

Non-finite scores (NaN or -inf: a pose without any feature) are treated as the lowest score:
the model maps them to its ``score_floor`` (one nat below the lowest finite fitted score), the
AUC ranks them below every finite score.

The fit is a two-parameter logistic regression solved by Newton's method with backtracking on
the standardized score, with a small ridge penalty on the slope so that separable data (every
success scoring above every failure) still converges to finite parameters. The slope is
constrained to be nonnegative: a higher score never predicts a lower success probability. Data
with a single class gives a constant model rather than an error, so a scene where every image
localizes does not stop a pipeline.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, fields

import numpy as np

log = logging.getLogger(__name__)

#: Success rates used for a constant model are clipped to [RATE_CLIP, 1 - RATE_CLIP].
RATE_CLIP = 1e-3


def sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function ``1 / (1 + exp(-x))``, elementwise, without overflow for any |x|."""
    x = np.asarray(x, dtype=float)
    e = np.exp(-np.abs(x))  # in (0, 1]: never overflows
    return np.where(x >= 0.0, 1.0 / (1.0 + e), e / (1.0 + e))


def _logit(p: float) -> float:
    return float(np.log(p) - np.log1p(-p))


def _as_floor(scores: np.ndarray, floor: float) -> np.ndarray:
    s = np.asarray(scores, dtype=float)
    return np.where(np.isfinite(s), s, floor)


@dataclass(frozen=True)
class SuccessModel:
    """Logistic model of localization success given the localizability score.

    Attributes:
        intercept: logit of the success probability at score 0.
        slope: increase of the logit per nat of score, >= 0.
        n: number of samples the model was fitted on.
        successes: how many of them localized.
        auc: ROC AUC of the score on the fitting data (NaN when it had one class only).
        score_floor: finite score (nats) that non-finite scores are mapped to.
    """

    intercept: float
    slope: float
    n: int
    successes: int
    auc: float
    score_floor: float

    def __post_init__(self) -> None:
        for name in ("intercept", "slope", "score_floor"):
            if not np.isfinite(float(getattr(self, name))):
                raise ValueError(f"SuccessModel.{name} must be finite")
        if not float(self.slope) >= 0.0:
            raise ValueError("SuccessModel.slope must be >= 0")
        if not 0 <= int(self.successes) <= int(self.n):
            raise ValueError("SuccessModel: need 0 <= successes <= n")

    def logit(self, scores: np.ndarray) -> np.ndarray:
        """``intercept + slope * s`` of (...) scores (nats); non-finite ones use ``score_floor``."""
        return self.intercept + self.slope * _as_floor(scores, self.score_floor)

    def probability(self, scores: np.ndarray) -> np.ndarray:
        """P(success) in [0, 1] of (...) scores in nats; non-finite scores use ``score_floor``."""
        return sigmoid(self.logit(scores))

    def probability_increase(self, scores: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """``P(s + g) - P(s)`` of (...) scores ``s`` and score increases ``g >= 0`` (nats).

        Computed as ``sigmoid(b) sigmoid(-a) (1 - exp(a - b))`` with ``a``, ``b`` the logits
        before and after, which keeps full relative precision when both probabilities are close
        to 0 or to 1 (a plain difference would cancel). Always >= 0 for ``g >= 0``.
        """
        a = self.logit(scores)
        g = np.asarray(gains, dtype=float)
        if self.slope == 0.0:
            return np.zeros(np.broadcast(a, g).shape)
        b = a + self.slope * g
        return sigmoid(b) * sigmoid(-a) * -np.expm1(a - b)

    def to_json(self) -> dict:
        """Plain-JSON dict (a NaN AUC becomes ``None``); :meth:`from_json` inverts it exactly."""
        d = asdict(self)
        d["intercept"], d["slope"], d["score_floor"] = (
            float(self.intercept), float(self.slope), float(self.score_floor))
        d["n"], d["successes"] = int(self.n), int(self.successes)
        d["auc"] = None if np.isnan(self.auc) else float(self.auc)
        return d

    @classmethod
    def from_json(cls, d: dict) -> "SuccessModel":
        """Inverse of :meth:`to_json`. Raises ValueError on missing or unknown keys."""
        names = {f.name for f in fields(cls)}
        if set(d) != names:
            raise ValueError(f"SuccessModel.from_json: expected keys {sorted(names)}, "
                             f"got {sorted(d)}")
        auc = float("nan") if d["auc"] is None else float(d["auc"])
        return cls(intercept=float(d["intercept"]), slope=float(d["slope"]), n=int(d["n"]),
                   successes=int(d["successes"]), auc=auc, score_floor=float(d["score_floor"]))


def _inputs(scores: np.ndarray, success: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(scores, dtype=float).reshape(-1)
    y = np.asarray(success).reshape(-1)
    if s.shape != y.shape:
        raise ValueError(f"scores ({s.shape[0]}) and success ({y.shape[0]}) lengths differ")
    return s, y.astype(bool)


def roc_auc(scores: np.ndarray, success: np.ndarray) -> float:
    """ROC AUC of ``scores`` for ``success``: P(score of a success > score of a failure).

    Mann-Whitney statistic with ties counted 1/2; non-finite scores rank below every finite one
    (and tie with each other). NaN when either class is empty.
    """
    s, y = _inputs(scores, success)
    n1 = int(y.sum())
    n0 = y.shape[0] - n1
    if n1 == 0 or n0 == 0:
        return float("nan")
    s = np.where(np.isfinite(s), s, -np.inf)
    _, inv, counts = np.unique(s, return_inverse=True, return_counts=True)
    # Average 1-based rank of each distinct value: ranks first..last share their mean.
    last = np.cumsum(counts)
    avg = last - (counts - 1) / 2.0
    rank_sum = float(avg[inv.reshape(-1)][y].sum())
    return (rank_sum - n1 * (n1 + 1) / 2.0) / (n1 * n0)


def calibration_curve(scores: np.ndarray, success: np.ndarray, bins: int = 10) -> dict:
    """Observed success rate per equal-count score bin.

    Bin edges are the score quantiles at ``0, 1/bins, ..., 1``; equal scores always share a bin,
    so with many ties some bins are empty and are dropped. Non-finite scores count as one nat
    below the lowest finite score.

    Args:
        scores: (n,) localizability scores, nats.
        success: (n,) bool.
        bins: number of quantile bins, >= 1.

    Returns:
        dict of (b,) arrays, b <= bins, in increasing score: ``score_mean`` (nats),
        ``success_rate`` in [0, 1] and ``count`` (int, summing to n).
    """
    if int(bins) != bins or bins < 1:
        raise ValueError(f"bins = {bins}: need a positive integer")
    s, y = _inputs(scores, success)
    if s.size == 0:
        return {"score_mean": np.zeros(0), "success_rate": np.zeros(0),
                "count": np.zeros(0, dtype=np.int64)}
    fin = np.isfinite(s)
    s = _as_floor(s, float(s[fin].min()) - 1.0 if fin.any() else 0.0)
    edges = np.quantile(s, np.linspace(0.0, 1.0, int(bins) + 1))
    b = np.searchsorted(edges[1:-1], s, side="right")  # bin i holds edges[i] <= s < edges[i+1]
    count = np.bincount(b, minlength=int(bins))
    keep = count > 0
    ssum = np.bincount(b, weights=s, minlength=int(bins))
    ysum = np.bincount(b, weights=y.astype(float), minlength=int(bins))
    return {"score_mean": ssum[keep] / count[keep], "success_rate": ysum[keep] / count[keep],
            "count": count[keep].astype(np.int64)}


def _newton_logistic(z: np.ndarray, y: np.ndarray, ridge: float,
                     max_iter: int = 200, tol: float = 1e-10) -> tuple[float, float, bool]:
    """Penalized logistic regression of y on standardized z: minimizes
    ``mean(log(1 + e^x) - y x) + ridge/2 b^2`` with ``x = a + b z``. Returns (a, b, converged)."""
    yf = y.astype(float)
    rate = float(np.clip(yf.mean(), RATE_CLIP, 1.0 - RATE_CLIP))
    theta = np.array([_logit(rate), 0.0])
    X = np.stack([np.ones_like(z), z], axis=1)

    def objective(t: np.ndarray) -> float:
        x = X @ t
        return float(np.mean(np.logaddexp(0.0, x) - yf * x) + 0.5 * ridge * t[1] ** 2)

    f = objective(theta)
    for _ in range(max_iter):
        p = sigmoid(X @ theta)
        grad = X.T @ (p - yf) / z.size + np.array([0.0, ridge * theta[1]])
        w = p * (1.0 - p)
        H = (X.T * w) @ X / z.size + np.diag([1e-12, ridge + 1e-12])
        step = np.linalg.solve(H, grad)
        t = 1.0
        while True:  # backtracking (Armijo) line search: the objective never increases
            cand = theta - t * step
            fc = objective(cand)
            if fc <= f - 1e-4 * t * float(grad @ step):
                break
            t *= 0.5
            if t < 1e-10:  # no decrease left at floating-point precision: at the optimum
                return float(theta[0]), float(theta[1]), True
        done = np.max(np.abs(cand - theta)) <= tol * (1.0 + np.max(np.abs(theta)))
        theta, f = cand, fc
        if done:
            return float(theta[0]), float(theta[1]), True
    return float(theta[0]), float(theta[1]), False


def fit_success_model(scores: np.ndarray, success: np.ndarray,
                      ridge: float = 1e-4) -> SuccessModel:
    """Fit ``P(success | s) = sigmoid(intercept + slope s)`` by penalized logistic regression.

    Args:
        scores: (n,) localizability scores (nats) of the fitting samples; NaN / -inf allowed
            (mapped to ``score_floor`` = lowest finite score - 1, or 0.0 if none is finite).
        success: (n,) bool, whether each sample localized.
        ridge: penalty ``ridge/2 b^2`` on the slope ``b`` of the *standardized* score, added to
            the mean negative log-likelihood (so its effect does not grow with n). Must be > 0.

    Returns:
        :class:`SuccessModel`. With one class only, or all scores equal, the constant model
        (slope 0, intercept = logit of the success rate clipped to [1e-3, 1 - 1e-3]) with a
        warning. If the best slope is negative, the constrained optimum (slope 0, intercept =
        logit of the unclipped success rate: the objective is convex, so the optimum over
        slope >= 0 lies on slope = 0) with a warning.

    Raises:
        ValueError: fewer than 2 samples, mismatched lengths, or ridge <= 0.
    """
    s, y = _inputs(scores, success)
    n = int(s.shape[0])
    if n < 2:
        raise ValueError(f"fit_success_model: need at least 2 samples, got {n}")
    if not float(ridge) > 0.0:
        raise ValueError(f"fit_success_model: ridge = {ridge} must be > 0")
    fin = np.isfinite(s)
    floor = float(s[fin].min()) - 1.0 if fin.any() else 0.0
    s = _as_floor(s, floor)
    k = int(y.sum())
    auc = roc_auc(s, y)

    def constant(why: str, clip: bool = True) -> SuccessModel:
        rate = float(np.clip(k / n, RATE_CLIP, 1.0 - RATE_CLIP)) if clip else k / n
        log.warning("fit_success_model: %s; using the constant model P = %.4f", why, rate)
        return SuccessModel(_logit(rate), 0.0, n, k, auc, floor)

    if k == 0 or k == n:
        return constant(f"all {n} samples {'localized' if k else 'failed'}")
    mu, sd = float(s.mean()), float(s.std())
    if not sd > 1e-12 * max(1.0, abs(mu)):
        return constant("all scores are equal")
    a, b, ok = _newton_logistic((s - mu) / sd, y, float(ridge))
    if not ok:
        log.warning("fit_success_model: Newton did not converge; using the last iterate")
    if b < 0.0:
        # Intercept-only maximum likelihood: logit of the rate (both classes present, no clip).
        return constant(f"the fitted slope is negative ({b / sd:.4g} per nat)", clip=False)
    return SuccessModel(a - b * mu / sd, b / sd, n, k, auc, floor)


__all__ = ["SuccessModel", "calibration_curve", "fit_success_model", "roc_auc", "sigmoid"]
