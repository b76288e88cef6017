"""``python -m replay.cli`` is ``bslam``."""

from replay.cli import main

main()
