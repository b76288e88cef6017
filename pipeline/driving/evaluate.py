"""How good a driving map is: a 2-D similarity fit to truth, and the batch optimum from truth.

:func:`similarity_fit` is the least-squares similarity (rotation, scale, translation; no
reflection) from estimated points to true ones (Umeyama's closed form).
:func:`batch_from_truth` solves the estimator's own factors with GTSAM's Levenberg-Marquardt,
started from the true poses and landmarks: the optimum the data allows, the yardstick of the
accuracy goals.
"""

from __future__ import annotations

from collections.abc import Mapping

import gtsam
import numpy as np
from numpy.typing import NDArray

from pipeline.driving.factors import keyframe_key
from pipeline.driving.odometry import between, compose
from pipeline.joint.graph import landmark_key


def similarity_fit(
    est: NDArray[np.float64], truth: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The points ``est`` (n, 2) moved by the similarity that best fits them to ``truth``
    (n, 2) (n >= 2), and each point's error (n,) after the fit (truth's units)."""
    mu_e, mu_t = est.mean(axis=0), truth.mean(axis=0)
    a, b = est - mu_e, truth - mu_t
    cov = b.T @ a / est.shape[0]
    u, s, vt = np.linalg.svd(cov)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rot = u @ d @ vt
    var_e = float((a * a).sum()) / est.shape[0]
    scale = float(np.trace(np.diag(s) @ d)) / var_e
    moved = (scale * (rot @ a.T)).T + mu_t
    return moved, np.hypot(*(moved - truth).T)


def batch_from_truth(
    graph: gtsam.NonlinearFactorGraph,
    landmark_index: Mapping[str, int],
    keyframe_truth: NDArray[np.float64],
    landmarks_truth: Mapping[str, NDArray[np.float64]],
    first_pose_map: NDArray[np.float64],
) -> dict[str, NDArray[np.float64]]:
    """Levenberg-Marquardt on ``graph`` from the truth; the landmarks (2,) it ends at (map frame).

    Parameters
    ----------
    graph : gtsam.NonlinearFactorGraph
        The estimator's factors (keyframes ``x(k)``, landmarks ``l(j)``).
    landmark_index : dict name -> j
        The landmarks in the graph and their key indices.
    keyframe_truth : (k, 3) float
        True keyframe poses (world).
    landmarks_truth : dict name -> (2,)
        True landmark positions (world).
    first_pose_map : (3,)
        Keyframe 0's pose in the map frame (its gauge): the truth is moved there rigidly.
    """

    def moved(pose: NDArray[np.float64]) -> NDArray[np.float64]:
        return compose(first_pose_map, between(keyframe_truth[0], pose))

    values = gtsam.Values()
    for k, pose in enumerate(keyframe_truth):
        values.insert(keyframe_key(k), gtsam.Pose2(*moved(pose)))
    for name, j in landmark_index.items():
        p = moved(np.array([*landmarks_truth[name], 0.0]))
        values.insert(landmark_key(j), p[:2].copy())
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(200)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return {n: np.asarray(result.atPoint2(landmark_key(j))) for n, j in landmark_index.items()}
