"""Old keyframes of a driving map leave iSAM2, folded into one linear prior.

:func:`drop_keyframes` takes the factors of an iSAM2 that touch the old keyframes (with the
prior of an earlier call), linearizes them at the current estimate and marginalizes the old
keyframes out (:func:`pipeline.joint.window.marginalize`): what they said about the landmarks
and the first keyframe kept becomes one ``LinearContainerFactor``. A new iSAM2 starts over the
other factors and that prior. The old keyframes' bearings are then linearized once: neither
relinearized nor re-weighted by the Huber loss again.
"""

from __future__ import annotations

from collections.abc import Sequence

import gtsam

from pipeline.joint.window import marginalize

#: Keyframes a driving map keeps in iSAM2 by default (``replay.defaults.KEYFRAME_WINDOW``; a
#: test holds them equal): late/early cost per keyframe 0.78x on a 10-minute drive
#: (docs/benchmarks.md).
DEFAULT_KEYFRAME_WINDOW = 50


def drop_keyframes(
    isam: gtsam.ISAM2, params: gtsam.ISAM2Params, old_keys: Sequence[int]
) -> tuple[gtsam.ISAM2, gtsam.Values]:
    """A new iSAM2 (with ``params``) over ``isam``'s factors with ``old_keys`` marginalized out,
    and the estimate of every variable (old ones included) at which they were."""
    values = isam.calculateEstimate()
    old = set(old_keys)
    factors = isam.getFactorsUnsafe()
    touching: list[gtsam.NonlinearFactor] = []
    rest = gtsam.NonlinearFactorGraph()
    for i in range(factors.size()):
        f = factors.at(i)
        if f is None:
            continue
        if isinstance(f, gtsam.LinearContainerFactor) or not old.isdisjoint(f.keys()):
            touching.append(f)
        else:
            rest.add(f)
    done = marginalize(touching, values, list(old_keys))
    if done.prior is not None:
        rest.add(done.prior)
    fresh = gtsam.ISAM2(params)
    fresh.update(rest, values.extract([k for k in list(values.keys()) if k not in old]))
    return fresh, values
