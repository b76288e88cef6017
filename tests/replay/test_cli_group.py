from __future__ import annotations

import subprocess
import sys

from click.testing import CliRunner

from replay.cli import cli


def test_help_lists_group() -> None:
    result = CliRunner().invoke(cli, ["--help"])
    assert result.exit_code == 0
    assert "Bearing-only SLAM" in result.output


def test_unknown_command_is_usage_error() -> None:
    result = CliRunner().invoke(cli, ["no-such-command"])
    assert result.exit_code == 2


def test_help_does_not_import_heavy_libraries() -> None:
    code = (
        "import sys; from replay.cli import cli\n"
        "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = ('scipy', 'rerun', 'cv2', 'matplotlib', 'dask', 'gtsam', 'jsonschema', 'numpy')\n"
        "heavy = [m for m in heavy if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_paper_estimator_does_not_import_gtsam() -> None:
    # gtsam (~0.3 s to import) is paid only by the commands that build a joint map
    code = (
        "import sys, numpy as np\n"
        "from pipeline.estimators import make_estimator\n"
        "from replay.stages import Runner\n"
        "make_estimator('paper', ['A', 'B'], ('A', 'B'), vision_error_rad=0.05,"
        " rng=np.random.default_rng(0))\n"
        "assert 'gtsam' not in sys.modules\n"
        "make_estimator('joint', ['A', 'B'], ('A', 'B'), vision_error_rad=0.05,"
        " rng=np.random.default_rng(0))\n"
        "assert 'gtsam' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
