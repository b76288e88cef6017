"""The paper's experiments and sweeps: many simulated logs, processed, compared, plotted.

``protocol`` builds the runs (scenario, seed, methods), ``run`` does one run (simulate, process,
score), ``results`` stores every error row, ``stats`` aggregates them, ``plots``/``rrd``/``report``
render them, ``paper`` ties the paper experiment together and ``sweep`` varies one parameter.
"""
