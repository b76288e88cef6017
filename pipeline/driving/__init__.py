"""A driving robot's map: keyframes from odometry, odometry and bearing factors in iSAM2.

Modules: ``keyframes`` (when odometry makes a keyframe), ``odometry`` (relative poses and the
wheel noise model), ``two_views`` (the impartial-PDF initialization from two views with any
known relative pose), ``factors`` (GTSAM factors of the driving graph), ``estimator``
(:class:`~pipeline.driving.estimator.DrivingSlam`), ``simulate`` (a synthetic driving robot
with a 360-degree bearing sensor), ``evaluate`` (similarity fit to truth, batch solve from
truth). ``gtsam`` is imported only by ``factors``, ``estimator`` and ``evaluate``.
"""
