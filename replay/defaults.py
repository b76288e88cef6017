"""Every default setting of the method and of imports, in one numpy-free module.

The command line (option defaults, so ``bslam --help`` loads no numpy), the Python API
(:class:`replay.records.MethodConfig`, which :func:`replay.process.process_log` takes), the
experiments' protocol and the importers all take their defaults from here, so that one log gives
one map whichever way it is processed (``tests/replay/test_api_equals_cli.py``).
:func:`pipeline.estimators.make_estimator` has no defaults: its caller gives every setting.
"""

from __future__ import annotations

#: Estimator names, the default first (``pipeline.estimators.ESTIMATORS``; a test holds them
#: equal).
ESTIMATORS = ("joint", "paper")
ESTIMATOR = ESTIMATORS[0]
#: Single-view priors (``pipeline.priors.PriorName``'s values; a test holds them equal), the
#: default first: the paper's impartial PDF.
PRIORS = ("impartial", "gaussian", "mixture")
PRIOR = PRIORS[0]
#: Particles per landmark in FR (after one movement) and in FL (the belief): the paper's
#: (``pipeline.fusion.PAPER_N_R`` and ``PAPER_N_L``; a test holds them equal).
N_R = 50
N_L = 300
#: Seed of a run's random generator.
SEED = 0
#: Joint estimator: std (degrees) of a prior on each commanded turn in place; None: turns free.
TURN_PRIOR_DEG: float | None = None
#: Joint estimator: relative std of a prior on each movement's length from its driven distance
#: (docs/method.md, the joint estimator: measured on the paper protocol); None: lengths free.
DISTANCE_PRIOR_REL: float | None = 0.05
#: Joint estimator: movements kept in the graph, older ones marginalized into a prior
#: (``pipeline.joint.window.DEFAULT_WINDOW``; a test holds them equal); 0 keeps every one.
JOINT_WINDOW = 100
#: Driving logs: keyframes kept in iSAM2, older ones marginalized
#: (``pipeline.driving.lag.DEFAULT_KEYFRAME_WINDOW``; a test holds them equal); 0 keeps every one.
KEYFRAME_WINDOW = 50

#: Bound eps (degrees) on the bearing error of an imported log whose source does not give one:
#: the impartial PDF's angular width, the paper's 3 deg. UTIAS MRCLAM's camera against its
#: motion-capture truth: 90% of each robot's bearings are within 0.84-2.91 deg (docs/RESULTS.md).
IMPORT_VISION_ERROR_DEG = 3.0
