"""``bslam import``: other formats in, ordinary bearing-slam logs out.

One module a job: :mod:`~replay.importers.source` (what every importer yields: the session and
its messages, provenance of the files read, the import error), :mod:`~replay.importers.text`
(reading text tables with line numbers), :mod:`~replay.importers.odometry` (integrating wheel
velocities into poses), one module per format (:mod:`~replay.importers.csv_files`,
:mod:`~replay.importers.mrclam`) and :mod:`~replay.importers.write` (the one path that writes
any import to a log). A new format is a module whose importer has ``inputs`` and ``read()``
(:class:`~replay.importers.source.Importer`); the CLI adds a subcommand that makes one.
"""
